"""The registry of tile strategies and policies: every list of names in the toolkit reads it.

A strategy is registered once (``register_strategy``): its GPU class, its kind, whether the mixed policies choose
among it, its option values (e.g. ray-cast reconstructions) and its CPU triangle estimate. Each strategy is also
the pure policy of the same name. A mixed policy is registered once (``register_policy``) with its per-tile rule.
The CLI's choices, the spec checks, the planner and the renderer ask the functions below, never a copied list.

A policy that ray casts every tile whose triangles outnumber its pixels twice, else rasterizes::

    def twice(columns, predicted, threshold):
        return heuristic_rule(columns, predicted, 2.0 * threshold)

    register_policy(PolicyEntry("heuristic2", "ray cast where triangles outnumber pixels twice", rule=twice))

after which ``terrabench render --method heuristic2`` and ``policies = ["heuristic2"]`` in a spec work (register
it in a module the command line imports). A strategy registers its GPU class the same way (``register_strategy``).

This module sits above ``raster`` and ``raycast`` (it imports them) and below the cost model and the
renderer (which find strategies only through it).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from hybrid.contract import FULL_RES, Kind, TileStrategy, TriangleEstimator
from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import HeightField
from hybrid.tiles.pyramid import TilePyramid
from raster.estimate import TileletTriangleEstimator
from raster.indexed import IndexedTileletStrategy
from raster.tilelets import TileletStrategy
from raster.tin import TinStrategy
from raster.trianglelist import TriangleListStrategy
from raycast import RECONSTRUCTIONS, RaycastStrategy

REFERENCE = "reference"
"""The method that is no policy: the full-resolution reference renderer."""

Rule = Callable[[Mapping[str, np.ndarray], Mapping[str, np.ndarray], float], list[str]]
"""A mixed policy's per-tile rule: (feature columns, predicted ms per candidate, threshold) -> strategy per tile."""


@dataclass(frozen=True)
class StrategyEntry:
    """One registered strategy: its GPU class, its kind, whether mixed policies choose among it, the values its
    choice-valued draw options take and, for raster strategies, a CPU triangle estimate."""

    name: str
    kind: Kind
    cls: Any  # the GPU class, satisfying TileStrategy structurally
    description: str
    triangle_estimator: Callable[[TilePyramid], TriangleEstimator] | None = None
    candidate: bool = False
    choices: Mapping[str, tuple[str, ...]] = field(default_factory=dict)

    @property
    def draw_options(self) -> frozenset[str]:
        """Names of the options its draw_tiles takes (the renderer's own, such as skirts, included)."""
        return self.cls.draw_options

    @functools.cached_property
    def option_names(self) -> frozenset[str]:
        """Names of its draw options a user sets: the fields of its options dataclass (``options_type``); read by
        every frame's option routing, so made once."""
        return frozenset(f.name for f in fields(self.cls.options_type))


@dataclass(frozen=True)
class PolicyEntry:
    """One registered mixed policy: a per-tile choice among the candidate strategies.

    rule: the choice from features and predictions (None: the cost model's hedged cheapest choice,
      ``hybrid.cost.planner.hedged_picks``); adapts: refits its cost model from the frames it draws (so runs
      vary its starting model); measures: times every tile every candidate way by default (an evaluation bound).
    """

    name: str
    description: str
    rule: Rule | None = None
    adapts: bool = False
    measures: bool = False


STRATEGIES: dict[str, StrategyEntry] = {}
MIXED: dict[str, PolicyEntry] = {}


def register_strategy(entry: StrategyEntry) -> StrategyEntry:
    """Add a strategy (and the pure policy of its name); a name already taken raises TerrabenchError."""
    if entry.name in STRATEGIES or entry.name in MIXED or entry.name == REFERENCE:
        raise TerrabenchError(f"name {entry.name!r} is already registered")
    STRATEGIES[entry.name] = entry
    return entry


def register_policy(entry: PolicyEntry) -> PolicyEntry:
    """Add a mixed policy; a name already taken raises TerrabenchError."""
    if entry.name in STRATEGIES or entry.name in MIXED or entry.name == REFERENCE:
        raise TerrabenchError(f"name {entry.name!r} is already registered")
    MIXED[entry.name] = entry
    return entry


def unregister(name: str) -> None:
    """Remove a registered strategy or mixed policy (tests register toys and take them away again)."""
    STRATEGIES.pop(name, None)
    MIXED.pop(name, None)


def pure_policies() -> tuple[str, ...]:
    """Policies that draw every tile one way: one per registered strategy."""
    return tuple(STRATEGIES)


def mixed_policies() -> tuple[str, ...]:
    """Policies that choose a strategy per tile among the candidates."""
    return tuple(MIXED)


def policies() -> tuple[str, ...]:
    """Every policy a Renderer takes: the pure ones, then the mixed ones."""
    return pure_policies() + mixed_policies()


def methods() -> tuple[str, ...]:
    """Everything that renders a view: the reference, then every policy."""
    return (REFERENCE, *policies())


def adapting_policies() -> tuple[str, ...]:
    """Mixed policies that refit their cost model from the frames they draw."""
    return tuple(n for n, e in MIXED.items() if e.adapts)


def candidates() -> tuple[str, ...]:
    """The strategies a mixed policy chooses between."""
    return tuple(n for n, e in STRATEGIES.items() if e.candidate)


def strategies_of_kind(kind: str) -> tuple[str, ...]:
    """The strategies of one kind ('raster' or 'raycast')."""
    return tuple(n for n, e in STRATEGIES.items() if e.kind == kind)


def policy_strategies(policy: str) -> tuple[str, ...]:
    """The strategies a policy may draw with: its own, the candidates for a mixed one, none for the reference."""
    if policy in STRATEGIES:
        return (policy,)
    return candidates() if policy in MIXED else ()


def policies_taking(option: str) -> tuple[str, ...]:
    """Policies with a strategy that takes draw option ``option`` (e.g. ``full_res``: those drawing tilelets)."""
    return tuple(p for p in policies() if any(option in STRATEGIES[s].draw_options for s in policy_strategies(p)))


def option_choices(option: str) -> tuple[str, ...]:
    """The values a choice-valued draw option takes (e.g. ``reconstruction``), over every strategy, in order."""
    out: dict[str, None] = {}
    for e in STRATEGIES.values():
        out.update(dict.fromkeys(e.choices.get(option, ())))
    return tuple(out)


def policy_entry(name: str) -> PolicyEntry:
    """The registry entry of a mixed policy; unknown names raise TerrabenchError listing the known ones."""
    if name not in MIXED:
        raise TerrabenchError(f"unknown mixed policy {name!r}; available: {', '.join(MIXED)}")
    return MIXED[name]


def check_policy(name: str) -> None:
    """Raise TerrabenchError unless ``name`` is a registered policy."""
    if name not in STRATEGIES and name not in MIXED:
        raise TerrabenchError(f"unknown policy {name!r}; choose one of {', '.join(policies())}")


def strategy_entry(name: str) -> StrategyEntry:
    """The registry entry of a strategy name; unknown names raise TerrabenchError listing the known ones."""
    if name not in STRATEGIES:
        raise TerrabenchError(f"unknown strategy {name!r}; available: {', '.join(STRATEGIES)}")
    return STRATEGIES[name]


def make_strategy(name: str, ctx, hf: HeightField, **options) -> TileStrategy:
    """A strategy instance by registered name (options go to its constructor)."""
    return strategy_entry(name).cls(ctx, hf, **options)


def triangle_estimator(pyramid: TilePyramid, name: str = "raster", **options) -> TriangleEstimator:
    """The CPU triangle estimate of a raster strategy over a pyramid (no GL context needed); ``options`` as the
    strategy's draw options that shape its mesh (``full_res``)."""
    entry = strategy_entry(name)
    if entry.triangle_estimator is None:
        raise TerrabenchError(f"strategy {name!r} has no CPU triangle estimate")
    return entry.triangle_estimator(pyramid, **options)


def heuristic_rule(columns, predicted, threshold: float = 1.0) -> list[str]:
    """Dick et al.'s rule: ray cast a tile whose triangles outnumber its pixels by more than ``threshold``."""
    tri = np.asarray(columns["triangles"], dtype=np.float64)
    raster = ~(tri > threshold * np.maximum(columns["pixels"], 1.0)) & ~np.isnan(tri)
    return np.where(raster, "raster", "raycast").tolist()


def oracle_rule(columns, predicted, threshold: float = 1.0) -> list[str]:
    """The oracle's choice until the renderer has measured every tile: raster."""
    return ["raster"] * len(columns["pixels"])


TILELETS = {"full_res": FULL_RES}
for _entry in (
    StrategyEntry(
        "raster",
        "raster",
        IndexedTileletStrategy,
        "GPU-selected restricted-quadtree tilelets drawn as indexed triangles (no geometry shader)",
        TileletTriangleEstimator,
        candidate=True,
        choices=TILELETS,
    ),
    StrategyEntry(
        "raster_gs",
        "raster",
        TileletStrategy,
        "GPU-selected restricted-quadtree tilelets through the geometry shader (the paper's path)",
        TileletTriangleEstimator,
        candidate=True,
        choices=TILELETS,
    ),
    StrategyEntry(
        "raycast",
        "raycast",
        RaycastStrategy,
        "maximum-mipmap ray casting (Dick et al.)",
        candidate=True,
        choices={"reconstruction": RECONSTRUCTIONS},
    ),
    StrategyEntry("fullres", "raster", TriangleListStrategy, "full-resolution indexed triangle list per tile"),
    StrategyEntry("tin", "raster", TinStrategy, "decimated TIN per tile (may crack at tile borders)"),
):
    register_strategy(_entry)
for _policy in (
    PolicyEntry("hybrid", "the candidate the cost model predicts cheapest per tile, hedged by its error", adapts=True),
    PolicyEntry(
        "heuristic", "Dick et al.'s fixed rule: ray cast where triangles outnumber pixels", rule=heuristic_rule
    ),
    PolicyEntry(
        "oracle",
        "each tile timed every candidate way inside frames, the cheapest kept",
        rule=oracle_rule,
        measures=True,
    ),
):
    register_policy(_policy)
