"""Stress specs (kind = "stress" in a spec file): scenes x views x methods of ``experiments.stress``, checked."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

from hybrid.camera.view import parse_size
from hybrid.errors import TerrabenchError

from .spec_keys import checked_list


@dataclass
class StressSpec:
    """A stress experiment (kind = "stress"): scenes x views x methods, see experiments.stress."""

    name: str
    scenes: list
    views: list
    methods: list
    size_samples: int = 257
    size: str = "320x180"
    tile_size: int = 64

    def to_dict(self) -> dict:
        """Plain form."""
        return {"kind": "stress", **asdict(self)}


def parse_stress_spec(d: dict, source: str) -> StressSpec:
    """Check a kind = "stress" spec: names from experiments.stress, sizes in range."""
    from .stress import METHODS, SCENES, VIEWS

    known = set(StressSpec.__dataclass_fields__) | {"kind"}
    if set(d) - known:
        raise TerrabenchError(f"{source}: unknown keys {sorted(set(d) - known)}; known: {sorted(known)}")
    kw = {"name": d.get("name", Path(source).stem)}
    for key, allowed in (("scenes", SCENES), ("views", VIEWS), ("methods", METHODS)):
        v = checked_list(d, key, str)
        bad = [x for x in (v or []) if x not in allowed]
        if bad:
            raise TerrabenchError(f"{source}: unknown {key} {bad}; choose from {', '.join(allowed)}")
        kw[key] = v or list(allowed)
    if "size_samples" in d:
        v = d["size_samples"]
        if isinstance(v, bool) or not isinstance(v, int) or not (17 <= v <= 4097):
            raise TerrabenchError(f"{source}: 'size_samples' must be an integer in [17, 4097], got {v!r}")
        kw["size_samples"] = v
    if "size" in d:
        parse_size(d["size"], f"{source}: size")
        kw["size"] = str(d["size"])
    if "tile_size" in d:
        v = d["tile_size"]
        if isinstance(v, bool) or not isinstance(v, int) or v < 2 or v & (v - 1):
            raise TerrabenchError(f"{source}: 'tile_size' must be a power of two >= 2, got {v!r}")
        kw["tile_size"] = v
    return StressSpec(**kw)
