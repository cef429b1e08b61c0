"""Drawing one frame: select tiles for a view, upload what is missing, let each strategy draw its tiles.

Frame time (``wall_ms``) is what a user waits for a frame: the CPU planning of the frame (tile selection,
and for the mixed policies the features and choices) plus the drawing, wall clock with ctx.finish() on
both sides. Uploads of tiles not yet resident are not in it (counted apart as ``uploaded``).

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

from .errors import TerrabenchError
from .heightfield import HeightField
from .pyramid import TilePyramid
from .shaders import load_source
from .target import FrameTarget, RenderResult
from .tiletree import DEFAULT_TAU, select_tiles
from .timing import timed
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


def make_strategy(name: str, ctx, hf: HeightField):
    """A strategy instance by registered name."""
    if name not in STRATEGIES:
        raise TerrabenchError(f"unknown strategy {name!r}; available: {', '.join(sorted(STRATEGIES)) or 'none'}")
    return STRATEGIES[name](ctx, hf, shading_source())


class SingleStrategyRenderer:
    """Renders whole views with one strategy over the tile tree (resident tiles kept between frames)."""

    def __init__(self, ctx, hf: HeightField, strategy: str, tile_size: int = 256, pyramid: TilePyramid | None = None,
                 **draw_options):
        self.ctx, self.hf = ctx, hf
        self.name = strategy
        self.strategy = make_strategy(strategy, ctx, hf)
        self.pyramid = pyramid or TilePyramid(hf, tile_size)
        self.resident: dict = {}
        self.draw_options = draw_options

    def render(self, view: View, tau: float = DEFAULT_TAU, **options) -> RenderResult:
        """Draw the view and read it back (colour, distance) with the strategy's counters in stats."""
        t_plan = time.perf_counter()
        selected = select_tiles(self.pyramid, view, tau)
        plan_ms = (time.perf_counter() - t_plan) * 1e3
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
            opts = {**self.draw_options, **options}
            if self.name == "raster":
                opts.setdefault("leaf_tau", tau)          # the in-tile quadtree follows the frame's bound
                opts.setdefault("count_culled", False)    # the CPU mirror of GPU culling is a check, not timed
            counters, draw, gpu = timed(self.ctx, lambda: self.strategy.draw_tiles(target, view, items, **opts))
            counters = counters or {}
            stats = {"tiles": len(items), f"tiles_{self.name}": len(items), "uploaded": uploaded,
                     "wall_ms": plan_ms + draw, "plan_ms": plan_ms, "draw_ms": draw, "gpu_ms": gpu,
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


class ReferenceFrameRenderer:
    """The reference renderer behind the same render(view, tau) interface, timed like the strategies."""

    def __init__(self, ctx, hf: HeightField):
        from .reference import ReferenceRenderer
        self.ctx, self.ref = ctx, ReferenceRenderer(ctx, hf)

    def render(self, view: View, tau: float = DEFAULT_TAU, **options) -> RenderResult:
        """Draw the full-resolution surface (tau is ignored: the reference has no level of detail)."""
        target = FrameTarget(self.ctx, view.width, view.height)
        try:
            target.clear()
            _, wall, gpu = timed(self.ctx, lambda: self.ref.draw(target, view, options.get("mode")))
            return target.read(view, {"wall_ms": wall, "plan_ms": 0.0, "draw_ms": wall, "gpu_ms": gpu,
                                      "triangles": self.ref.triangles, "tiles": 1, "gpu_bytes": self.ref.nbytes})
        finally:
            target.release()

    def release(self) -> None:
        """Free the GPU objects."""
        self.ref.release()


def make_renderer(ctx, hf: HeightField, policy: str, tile_size: int = 256, reconstruction: str = "triangles",
                  **options):
    """A whole-view renderer for a policy: reference, a single strategy, or a hybrid policy."""
    if policy == "reference":
        return ReferenceFrameRenderer(ctx, hf)
    if policy in ("hybrid", "heuristic", "oracle"):
        from .hybrid_frame import HybridRenderer
        return HybridRenderer(ctx, hf, policy, tile_size=tile_size, reconstruction=reconstruction, **options)
    if policy == "raycast":
        return SingleStrategyRenderer(ctx, hf, "raycast", tile_size, reconstruction=reconstruction, **options)
    return SingleStrategyRenderer(ctx, hf, policy, tile_size, **options)


from . import strategies  # noqa: E402,F401  (registers the raster and raycast strategies)
