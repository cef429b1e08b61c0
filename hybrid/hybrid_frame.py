"""The hybrid frame: each tile drawn by the strategy chosen for it, both into one colour + depth buffer.

Order within a frame: the raster tiles first (front to back), then the ray-cast tiles front to back with
the tile-ID pre-pass, so no ray is cast where a nearer raster tile already covers the pixel. Both strategies
write depth from the same reversed-Z projection, so a world point has one depth whichever draws it.
"""
from __future__ import annotations

import time

import numpy as np

from .costmodel import CostModel, load_cost_model
from .frame import make_strategy
from .glcontext import gl_info
from .heightfield import HeightField
from .planner import RasterTriangleEstimator, TilePlan, plan_frame
from .pyramid import TilePyramid
from .residency import ResidencyCache
from .timing import timed
from .target import FrameTarget, RenderResult
from .pyramid import EDGE_E, EDGE_N, EDGE_S, EDGE_W
from .tiletree import DEFAULT_TAU, edge_neighbours
from .view import View

STRATEGY_CODES = {"raster": 1, "raycast": 2}


class HybridRenderer:
    """Whole views drawn tile by tile with a policy's choice of strategy, with exact GPU-memory accounting."""

    def __init__(self, ctx, hf: HeightField, policy: str = "hybrid", tile_size: int = 256,
                 reconstruction: str = "triangles", cost_model: CostModel | None = None,
                 budget_bytes: int | None = None, threshold: float = 1.0, prepass: bool = True,
                 pyramid: TilePyramid | None = None, oracle_repeats: int = 3, mode: str | None = None):
        self.ctx, self.hf, self.policy = ctx, hf, policy
        self.pyramid = pyramid or TilePyramid(hf, tile_size)
        self.strategies = {"raster": make_strategy("raster", ctx, hf), "raycast": make_strategy("raycast", ctx, hf)}
        shading = {} if mode is None else {"mode": mode}      # one shading mode for both strategies
        self.options = {"raster": {"count_culled": False, **shading},
                        "raycast": {"reconstruction": reconstruction, "prepass": prepass, **shading}}
        self.model = cost_model or load_cost_model(gl_info(ctx).renderer)
        self.cache = ResidencyCache(budget_bytes)
        self.threshold = threshold
        self.oracle_repeats = oracle_repeats
        self._tiles: dict = {}
        self.triangles = RasterTriangleEstimator(self.pyramid)

    # --- planning (CPU) ---------------------------------------------------------------------------
    def tile(self, key):
        """The pyramid tile (CPU copy, cached)."""
        if key not in self._tiles:
            self._tiles[key] = self.pyramid.tile(key)
        return self._tiles[key]

    def plan(self, view: View, tau: float = DEFAULT_TAU) -> list[TilePlan]:
        """The frame's tiles with features, predicted costs and choices."""
        return plan_frame(self.pyramid, view, self.model, self.triangles, self.policy, tau, self.threshold)

    # --- drawing ----------------------------------------------------------------------------------
    def _resident(self, name, key, pinned):
        return self.cache.get(name, self.strategies[name], key, lambda: self.tile(key), pinned)

    def _opts(self, name: str, tau: float) -> dict:
        return {**self.options[name], "leaf_tau": tau} if name == "raster" else self.options[name]

    def skirts(self, plans: list[TilePlan]) -> dict:
        """Edge bits of every raster tile that touches a ray-cast tile: skirts close the seam there."""
        choice = {p.key: p.choice for p in plans}
        keys = set(choice)
        out = {}
        for p in plans:
            if p.choice != "raster":
                continue
            bits = 0
            for bit, dx, dy in ((EDGE_W, -1, 0), (EDGE_E, 1, 0), (EDGE_S, 0, -1), (EDGE_N, 0, 1)):
                if any(choice[k] == "raycast" for k in edge_neighbours(keys, p.key, dx, dy, self.pyramid.max_level)):
                    bits |= bit
            if bits:
                out[p.key] = bits
        return out

    def _draw(self, target, view, plans: list[TilePlan], pinned, tau) -> dict:
        counters: dict = {}
        skirts = self.skirts(plans)
        for name in ("raster", "raycast"):
            items = [(self._resident(name, p.key, pinned), self.tile(p.key), p.selected) for p in plans if p.choice == name]
            if items:
                opts = self._opts(name, tau)
                if name == "raster" and skirts:
                    opts = {**opts, "skirts": skirts}
                c = self.strategies[name].draw_tiles(target, view, items, **opts) or {}
                for k, v in c.items():
                    if isinstance(v, (int, float, np.integer, np.floating)):
                        counters[k] = counters.get(k, 0) + v
        return counters

    def time_draw(self, view: View, plans: list[TilePlan], name: str, target: FrameTarget, pinned=frozenset(),
                  tau: float = DEFAULT_TAU) -> float:
        """Median ms of drawing the plans' tiles with one strategy in one call: the GL timer query on real
        GPUs, the wall clock around ctx.finish() on CPU rasterizers (where timer queries are wrong)."""
        items = [(self._resident(name, p.key, pinned), self.tile(p.key), p.selected) for p in plans]
        times = []
        for _ in range(self.oracle_repeats):
            target.clear()
            target.use()
            _, wall, gpu = timed(self.ctx, lambda: self.strategies[name].draw_tiles(target, view, items,
                                                                                    **self._opts(name, tau)))
            times.append(wall if gpu is None else gpu)
        return float(np.median(times))

    def render(self, view: View, tau: float = DEFAULT_TAU, measure: bool = False, maps: bool = False) -> RenderResult:
        """Draw the view and read it back; stats carry counters, memory and one row per tile.

        With ``measure`` (always for the oracle) every tile is also timed alone both ways; with ``maps`` the
        result also carries the per-pixel strategy map (two extra untimed renders).
        """
        t_plan = time.perf_counter()
        plans = self.plan(view, tau)
        plan_ms = (time.perf_counter() - t_plan) * 1e3
        pinned = {(p.choice, p.key) for p in plans}
        target = FrameTarget(self.ctx, view.width, view.height)
        together = {}
        try:
            if measure or self.policy == "oracle":
                pinned |= {(n, p.key) for p in plans for n in ("raster", "raycast")}
                for p in plans:
                    p.measured = {n: self.time_draw(view, [p], n, target, pinned, tau) for n in ("raster", "raycast")}
                    if self.policy == "oracle":
                        p.choice = min(p.measured, key=p.measured.get)
            if measure and plans:
                for n in ("raster", "raycast"):
                    together[f"together_{n}_ms"] = self.time_draw(view, plans, n, target, pinned, tau)
            # upload everything first so the timed frame measures drawing only
            for p in plans:
                self._resident(p.choice, p.key, pinned)
            target.clear()
            target.use()
            counters, draw, gpu = timed(self.ctx, lambda: self._draw(target, view, plans, pinned, tau))
            by = self.cache.bytes_by_strategy()
            n_r = sum(p.choice == "raster" for p in plans)
            stats = {"wall_ms": plan_ms + draw, "plan_ms": plan_ms, "draw_ms": draw, "gpu_ms": gpu, "tiles": len(plans), "tiles_raster": n_r, "tiles_raycast": len(plans) - n_r,
                     "gpu_bytes": self.cache.bytes, "gpu_bytes_raster": by.get("raster", 0),
                     "gpu_bytes_raycast": by.get("raycast", 0), "uploads": self.cache.stats.uploads,
                     "evictions": self.cache.stats.evictions,
                     "pred_ms": self.model.frame_ms([p.predicted[p.choice] for p in plans], {p.choice for p in plans}),
                     **together, **counters,
                     "tile_rows": [p.row() for p in plans]}
            result = target.read(view, stats)
            if maps:
                result.maps = {"strategy": self.strategy_map(view, plans, tau)}
            return result
        finally:
            target.release()

    def strategy_map(self, view: View, plans: list[TilePlan], tau: float = DEFAULT_TAU) -> np.ndarray:
        """Per pixel: 0 no terrain, 1 drawn by a raster tile, 2 by a ray-cast tile (compares depth per strategy)."""
        depths = {}
        for name in ("raster", "raycast"):
            sub = [p for p in plans if p.choice == name]
            t = FrameTarget(self.ctx, view.width, view.height)
            try:
                t.clear()
                t.use()
                if sub:
                    items = [(self._resident(name, p.key, set()), self.tile(p.key), p.selected) for p in sub]
                    opts = self._opts(name, tau)
                    self.strategies[name].draw_tiles(t, view, items, **({**opts, "prepass": False}
                                                                        if name == "raycast" else opts))
                depths[name] = t.read_depth()
            finally:
                t.release()
        out = np.zeros((view.height, view.width), np.uint8)
        r, c = depths["raster"], depths["raycast"]
        out[(r > 0) & (r >= c)] = STRATEGY_CODES["raster"]
        out[(c > 0) & (c > r)] = STRATEGY_CODES["raycast"]
        return out

    def release(self) -> None:
        """Free resident tiles and strategies."""
        self.cache.clear()
        for s in self.strategies.values():
            s.release()
