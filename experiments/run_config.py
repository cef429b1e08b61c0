"""The configurations of a run as typed values: ``Config`` (a flights spec's) and ``EditConfig`` (an edit spec's).

Configurations travel as these through a run (a spec's ``configs()``, the groups of ``experiments.config_task``,
the tasks sent to a Dask cluster's workers, which pickle them). They become dicts only where a row is written
(``row``: the journal's frames and errors, the tables) and are read back from a row with ``of``. A row holds
exactly the fields, in their order, so the journals and tables a run writes keep their columns.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from typing import Any, Protocol, Self, cast

from .spec_keys import START_MODELS


class RunConfig(Protocol):
    """What the journal and the runners need of any configuration: its stable id, its policy and its row."""

    @property
    def config(self) -> str:
        """The configuration's stable id (its rows' ``config`` column)."""
        ...

    @property
    def policy(self) -> str:
        """The method it draws with."""
        ...

    def row(self) -> dict:
        """The configuration as a flat dict, fields in order."""
        ...


class RowForm:
    """A configuration dataclass's row form: ``of`` reads one from a row, ``row`` writes its fields in order."""

    @classmethod
    def of(cls, row: Mapping) -> Self:
        """The configuration of a row; keys that are no field (a frame's columns) are left out, and a field the row
        lacks takes its default."""
        return cls(**{f.name: row[f.name] for f in fields(cast(Any, cls)) if f.name in row})

    def row(self) -> dict:
        """The configuration as a flat dict, fields in order."""
        return asdict(cast(Any, self))


@dataclass(frozen=True)
class Config(RowForm):
    """One configuration of a run: a policy over one flight of one dataset at one size, tau and option set; ``config``
    is its stable id. Runs store it as a row (``row``), as spec.json and the journal hold it."""

    config: str
    dataset: str
    seed: int
    flight: str
    size: str
    tau: float
    reconstruction: str
    full_res: str
    policy: str
    start_model: str = START_MODELS[0]


@dataclass(frozen=True)
class EditConfig(RowForm):
    """One configuration of an edit run: a policy following the edit programme at one brush radius (m), or on the
    static terrain (``editing`` false, radius 0, brush "none"), with ``particles`` drawn on the terrain."""

    config: str
    dataset: str
    seed: int
    flight: str
    size: str
    tau: float
    policy: str
    editing: bool
    edit_radius: float
    brush: str
    particles: int
