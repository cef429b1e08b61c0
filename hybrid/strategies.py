"""The registry of tile strategies: name -> how to make it, what kind it is, and its CPU triangle estimate.

This module sits above ``raster`` and ``raycast`` (it imports them) and below the cost model and the
renderer (which find strategies only through it).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from hybrid.contract import Kind, TileStrategy, TriangleEstimator
from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import HeightField
from hybrid.tiles.pyramid import TilePyramid
from raster.estimate import TileletTriangleEstimator
from raster.indexed import IndexedTileletStrategy
from raster.tilelets import TileletStrategy
from raster.tin import TinStrategy
from raster.trianglelist import TriangleListStrategy
from raycast import RaycastStrategy


@dataclass(frozen=True)
class StrategyEntry:
    """One registered strategy: its GPU class, its kind and, for raster strategies, a CPU triangle estimate."""

    name: str
    kind: Kind
    cls: type
    description: str
    triangle_estimator: Callable[[TilePyramid], TriangleEstimator] | None = None

    @property
    def draw_options(self) -> frozenset[str]:
        """Names of the options its draw_tiles takes."""
        return self.cls.draw_options


STRATEGIES: dict[str, StrategyEntry] = {e.name: e for e in (
    StrategyEntry("raster", "raster", IndexedTileletStrategy,
                  "GPU-selected restricted-quadtree tilelets drawn as indexed triangles (no geometry shader)",
                  TileletTriangleEstimator),
    StrategyEntry("raster_gs", "raster", TileletStrategy,
                  "GPU-selected restricted-quadtree tilelets through the geometry shader (the paper's path)",
                  TileletTriangleEstimator),
    StrategyEntry("raycast", "raycast", RaycastStrategy, "maximum-mipmap ray casting (Dick et al.)"),
    StrategyEntry("fullres", "raster", TriangleListStrategy, "full-resolution indexed triangle list per tile"),
    StrategyEntry("tin", "raster", TinStrategy, "decimated TIN per tile (may crack at tile borders)"),
)}


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
