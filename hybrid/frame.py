"""Drawing one frame: select tiles for a view, upload what is missing, let each strategy draw its tiles.

Strategies are GPU classes from ``raster`` and ``raycast`` with one shape (duck-typed, no import of
hybrid on their side):

- ``upload(tile) -> gpu_tile``: put one ``hybrid.pyramid.Tile`` on the GPU; ``gpu_tile.nbytes`` is the
  exact byte count of every buffer and texture it allocated, ``gpu_tile.release()`` frees them.
- ``draw_tiles(target, view, items, **options) -> dict``: draw ``items``, a front-to-back list of
  ``(gpu_tile, tile, selected)`` with ``selected`` a ``hybrid.tiletree.SelectedTile``, into a bound
  ``hybrid.target.FrameTarget`` for a ``hybrid.view.View``; returns counters (triangles, rays, ...).
- ``release()``.

Strategies are registered by name in ``STRATEGIES`` (factory ``(ctx, hf, shading_source) -> strategy``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

from .errors import TerrabenchError
from .heightfield import HeightField
from .pyramid import TilePyramid
from .shaders import load_source
from .target import FrameTarget, RenderResult
from .tiletree import DEFAULT_TAU, select_tiles
from .view import View

STRATEGIES: dict = {}


def register_strategy(name: str):
    """Decorator: register a factory (ctx, hf, shading_source) -> strategy under ``name``."""
    def deco(factory):
        STRATEGIES[name] = factory
        return factory
    return deco


def shading_source() -> str:
    """GLSL text of the shared colour conventions (hybrid/shading.glsl) that every strategy includes."""
    return load_source("hybrid", "shading.glsl")


@dataclass
class FrameStats:
    """Counters of one frame."""

    tiles: int = 0
    wall_ms: float = 0.0
    uploaded: int = 0
    counters: dict = field(default_factory=dict)


class SingleStrategyRenderer:
    """Renders whole views with one strategy over the tile tree (resident tiles kept between frames)."""

    def __init__(self, ctx, hf: HeightField, strategy: str, tile_size: int = 256, pyramid: TilePyramid | None = None):
        if strategy not in STRATEGIES:
            raise TerrabenchError(f"unknown strategy {strategy!r}; available: {', '.join(sorted(STRATEGIES)) or 'none'}")
        self.ctx, self.hf = ctx, hf
        self.pyramid = pyramid or TilePyramid(hf, tile_size)
        self.strategy = STRATEGIES[strategy](ctx, hf, shading_source())
        self.resident: dict = {}

    def render(self, view: View, tau: float = DEFAULT_TAU, **options) -> RenderResult:
        """Draw the view and read it back (colour, distance) with the strategy's counters in stats."""
        selected = select_tiles(self.pyramid, view, tau)
        target = FrameTarget(self.ctx, view.width, view.height)
        try:
            uploaded = 0
            items = []
            for s in selected:
                if s.key not in self.resident:
                    tile = self.pyramid.tile(s.key)
                    self.resident[s.key] = (self.strategy.upload(tile), tile)
                    uploaded += 1
                g, tile = self.resident[s.key]
                items.append((g, tile, s))
            target.clear()
            target.use()
            self.ctx.finish()
            t0 = time.perf_counter()
            counters = self.strategy.draw_tiles(target, view, items, **options) or {}
            self.ctx.finish()
            wall = (time.perf_counter() - t0) * 1e3
            stats = {"tiles": len(items), "uploaded": uploaded, "wall_ms": wall,
                     "gpu_bytes": sum(g.nbytes for g, _ in self.resident.values()), **counters}
            return target.read(view, stats)
        finally:
            target.release()

    def release(self) -> None:
        """Free every resident tile and the strategy."""
        for g, _ in self.resident.values():
            g.release()
        self.resident.clear()
        self.strategy.release()


from . import strategies  # noqa: E402,F401  (registers the strategies of raster/ and raycast/)
