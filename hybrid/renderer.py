"""The renderer: every policy draws a view tile by tile into one colour + reversed-Z depth buffer.

A pure policy (raster, raycast, fullres, tin) is the per-tile choice with a single answer; the mixed policies
(hybrid, heuristic, oracle) choose per tile among the candidates raster, raster_gs and raycast (hybrid.cost.planner).
Within a frame the raster tiles are drawn first (front to back), then the ray-cast tiles front to back; with
the tile-ID pre-pass (off by default, raycast.options.prepass_default) no ray is cast where a nearer tile
already covers the pixel. Every strategy writes depth from the same reversed-Z projection, so a world point has
one depth whichever draws it.

Frame time (``wall_ms``) is what a user waits for a frame: the CPU planning (tile selection, and for the
mixed policies the features and choices) plus the drawing, wall clock with ctx.finish() on both sides.
Without an upload budget, tiles not yet resident are uploaded before the timed draw and counted apart
(``uploads``); with ``upload_budget_ms`` uploads are jobs run inside the frame within that budget
(``hybrid.streaming``), their time is part of ``wall_ms``, and tiles still waiting are drawn from a resident
ancestor (``fallback_tiles``); from a tile store, the store's loader thread is asked at the start of the frame
for the samples the frame lacks and for the slow host work of uploads and estimates (``hybrid.uploads.host_jobs``),
and an upload whose host work it has not yet done waits for it.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Mapping

import numpy as np

from hybrid import adaptive, oracle
from hybrid.camera.view import View
from hybrid.contract import DEFAULT_FULL_RES, DrawOptions, EditFollowing, TerrainChange, TileItem
from hybrid.cost.model import CostModel, load_cost_model
from hybrid.cost.online import AdaptOptions, OnlineModel
from hybrid.cost.planner import TilePlan, plan_frame, pure_slack
from hybrid.cost.reuse import REUSE_FRAMES, ChoiceReuse
from hybrid.draw_options import resolve_options, route_options
from hybrid.errors import TerrabenchError
from hybrid.frame_draw import timed_draw
from hybrid.frame_readback import frame_result, strategy_map
from hybrid.frame_stats import add_frame_costs, frame_stats
from hybrid.gl.context import gl_info
from hybrid.gl.target import FrameTarget, RenderResult
from hybrid.reference import ReferenceRenderer
from hybrid.residency import ResidencyCache, reserve_pools
from hybrid.strategies import (
    STRATEGIES,
    candidates,
    check_policy,
    make_strategy,
    mixed_policies,
    policy_entry,
    triangle_estimator,
)
from hybrid.streaming import make_resident
from hybrid.terrain.heightfield import HeightField
from hybrid.tiles.pyramid import EDGE_E, EDGE_N, EDGE_S, EDGE_W, TilePyramid
from hybrid.tiles.store import pyramid_for
from hybrid.tiles.tiletree import DEFAULT_TAU, edge_neighbours
from hybrid.uploads import JobCosts, fallback_selection, fallback_tile


class Renderer:
    """Whole views drawn tile by tile with a policy's choice of strategy; resident tiles within a byte budget.

    ``options`` are draw options of the strategies (``mode``, ``reconstruction``, ``prepass``, ``wireframe``,
    ...), each given to the strategies that take it. The hybrid reuses a clear pure choice for up to
    ``reuse_choice`` - 1 frames after the full plan that made it (``hybrid.cost.reuse``; 1: plan every frame).
    A renderer is a context manager; it cannot be used
    after ``release()``.
    """

    def __init__(
        self,
        ctx,
        hf: HeightField,
        policy: str = "hybrid",
        tile_size: int = 256,
        *,
        cost_model: CostModel | None = None,
        budget_bytes: int | None = None,
        threshold: float = 1.0,
        oracle_repeats: int = 3,
        pyramid: TilePyramid | None = None,
        upload_budget_ms: float | None = None,
        adapt: bool | AdaptOptions = True,
        reuse_choice: int = REUSE_FRAMES,
        strategy_options: Mapping[str, DrawOptions] | None = None,
        **options,
    ):
        check_policy(policy)
        self.ctx, self.hf, self.policy = ctx, hf, policy
        self.mixed = policy in mixed_policies()
        self.entry = policy_entry(policy) if self.mixed else None
        self._own_pyramid = pyramid is None  # made here: closed (its loader thread) on release
        self.pyramid = pyramid or pyramid_for(hf, tile_size)
        self.cache = ResidencyCache(budget_bytes)
        names = candidates() if self.mixed else (policy,)
        self.options = resolve_options(dict.fromkeys(names), strategy_options, options)
        self.strategies = {n: make_strategy(n, ctx, hf, **self.options[n].upload_options()) for n in names}
        self._model = cost_model or (load_cost_model(gl_info(ctx).renderer) if self.mixed else None)
        self.online = (
            OnlineModel(self._model, adapt if isinstance(adapt, AdaptOptions) else None)
            if adapt and self.entry is not None and self.entry.adapts and self._model is not None
            else None
        )
        hedged = self.entry is not None and self.entry.rule is None and not self.entry.measures
        self.reuse = ChoiceReuse(reuse_choice) if hedged and reuse_choice > 1 else None
        self.triangles = (
            triangle_estimator(self.pyramid, full_res=options.get("full_res", DEFAULT_FULL_RES)) if self.mixed else None
        )
        if self.triangles is not None and upload_budget_ms is not None and self.pyramid.background_loader:
            self.triangles.background = True  # blocks still to cut: the store's loader thread cuts them
        self.threshold = threshold
        self.oracle_repeats = int(oracle_repeats)
        if upload_budget_ms is not None and not (np.isfinite(upload_budget_ms) and upload_budget_ms >= 0):
            raise TerrabenchError(f"upload budget must be a finite number of ms >= 0, got {upload_budget_ms!r}")
        self.upload_budget_ms = upload_budget_ms
        if upload_budget_ms is not None and budget_bytes is not None:  # streaming: tile pools of the budget's size
            reserve_pools(self.strategies, budget_bytes, self.pyramid)
        self.job_costs = JobCosts()  # upload jobs' expected ms: a frame starts those that fit its budget
        self._fallbacks: dict = {}
        self._tiles: OrderedDict = OrderedDict()
        self._released = False
        self._eye: np.ndarray | None = None  # the last frame's eye (world metres): the camera's motion

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    @property
    def model(self) -> CostModel | None:
        """The cost model the choices read now: the adapted one of an adapting hybrid, else the one given or loaded."""
        return self.online.model if self.online is not None else self._model

    @model.setter
    def model(self, model: CostModel) -> None:
        """Choose by ``model`` from now on; an adapting hybrid starts learning again from it."""
        self._model = model
        if self.online is not None:
            self.online = OnlineModel(model, self.online.options)

    def _check_live(self) -> None:
        if self._released:
            raise TerrabenchError(f"this {self.policy} renderer was released; make a new one")

    def kind(self, name: str) -> str:
        """'raster' or 'raycast': how strategy ``name`` makes pixels."""
        return STRATEGIES[name].kind

    # --- planning (CPU) ---------------------------------------------------------------------------
    def tile(self, key):
        """The pyramid tile (CPU copy), cached: least recently used first out beyond a store's host budget."""
        if key in self._tiles:
            self._tiles.move_to_end(key)
            return self._tiles[key]
        t = self._tiles[key] = self.pyramid.tile(key)
        budget = self.pyramid.host_budget
        if budget is not None and len(self._tiles) > max(budget // max(t.heights.nbytes, 1), 256):
            self._tiles.popitem(last=False)
        return t

    # --- edits (hybrid.editing) ---------------------------------------------------------------------
    def tiles_changed(self, keys) -> None:
        """Drop the CPU copies of tiles whose samples or bounds changed (the pyramid followed an edit), and what a
        loader made ahead for the others' uploads (a raster node block reads its neighbours' samples too)."""
        for k in keys:
            self._tiles.pop(k, None)
        for t in self._tiles.values():
            getattr(t, "host", {}).clear()

    def follow_edit(self, name: str, change: TerrainChange) -> int:
        """Bring strategy ``name``'s resident tiles up to date after an edit the pyramid followed: in place where
        the strategy can, else uploaded again in their residency slots; returns how many were refreshed."""
        self._check_live()
        strategy = self.strategies[name]
        if not isinstance(strategy, EditFollowing):
            raise TerrabenchError(f"strategy {name!r} cannot follow an edit of the terrain (no follow_edit)")
        done, stale = strategy.follow_edit(change, self.cache.resident(name), self.tile)
        for key in stale:
            self.cache.replace(name, key, strategy.upload(self.tile(key)))
        return done + len(stale)

    def follow_estimate(self, change: TerrainChange) -> int:
        """Forget the triangle estimate's work for the tiles an edit changed; returns how many (0 when none kept)."""
        return 0 if self.triangles is None else self.triangles.follow_edit(change)

    def plan(self, view: View, tau: float = DEFAULT_TAU) -> list[TilePlan]:
        """The frame's tiles front to back with the policy's choices (and, when mixed, features and costs); when
        streaming, new tiles' estimates are prepared within the upload budget (the rest ray cast this frame)."""
        self._check_live()
        reused = self.reuse.take() if self.reuse is not None else None
        if reused is not None:  # a clear choice of the last full plan (hybrid.cost.reuse)
            return plan_frame(self.pyramid, view, None, None, reused, tau)
        model, budget = self.model, self.upload_budget_ms
        plans = plan_frame(
            self.pyramid, view, model, self.triangles, self.policy, tau, self.threshold, prep_budget_ms=budget
        )
        if self.reuse is not None and model is not None:
            clear = pure_slack(plans, model)
            online = self.online  # an adapting model: only once the chosen strategy's predictions hold
            quiet = online is None or clear is None or online.holds(clear[0])
            self.reuse.planned(clear, budget is None and quiet)
        return plans

    def skirts(self, plans: list[TilePlan]) -> dict:
        """Edge bits of every raster tile that touches a ray-cast tile: skirts close the seam there."""
        kind = {p.key: self.kind(p.choice) for p in plans}
        if len(set(kind.values())) < 2:
            return {}
        keys = set(kind)
        out = {}
        for p in plans:
            if kind[p.key] != "raster":
                continue
            bits = 0
            for bit, dx, dy in ((EDGE_W, -1, 0), (EDGE_E, 1, 0), (EDGE_S, 0, -1), (EDGE_N, 0, 1)):
                if any(kind[k] == "raycast" for k in edge_neighbours(keys, p.key, dx, dy, self.pyramid.max_level)):
                    bits |= bit
            if bits:
                out[p.key] = bits
        return out

    # --- drawing ----------------------------------------------------------------------------------
    def _resident(self, name, key, pinned):
        return self.cache.get(name, self.strategies[name], key, lambda: self.tile(key), pinned)

    def _items(self, name: str, plans: list[TilePlan], pinned) -> list[TileItem]:
        out = []
        for p in plans:
            anc = self._fallbacks.get(p.key)
            if anc is None:
                out.append(TileItem(self._resident(name, p.key, pinned), self.tile(p.key), p.selected))
            else:  # drawn from its resident ancestor, clipped to its own area
                z = self.pyramid.zrange(p.key) if self.kind(name) == "raycast" else None
                out.append(
                    TileItem(
                        self._resident(name, anc, pinned),
                        fallback_tile(self.tile(anc), self.pyramid.clip(p.key), z),
                        fallback_selection(p.selected, anc),
                    )
                )
        return out

    def _order(self) -> list[str]:
        """Strategy names in drawing order: raster kinds first, ray casting last."""
        return sorted(self.strategies, key=lambda n: self.kind(n) == "raycast")

    def time_draw(
        self,
        view: View,
        plans: list[TilePlan],
        name: str,
        target: FrameTarget,
        pinned=frozenset(),
        tau: float = DEFAULT_TAU,
    ) -> float:
        """Median ms of drawing the plans' tiles with one strategy in one call (``hybrid.oracle.time_draw``)."""
        self._check_live()
        return oracle.time_draw(self, view, plans, name, target, pinned, tau)

    def time_in_frame(
        self,
        view: View,
        plans: list[TilePlan],
        name: str,
        target: FrameTarget,
        pinned=frozenset(),
        tau: float = DEFAULT_TAU,
    ) -> tuple[np.ndarray, float]:
        """(per-tile ms, whole-frame ms) of one strategy inside a real frame (``hybrid.oracle.time_in_frames``)."""
        return self.time_in_frames(view, plans, [name], target, pinned, tau)[name]

    def time_in_frames(
        self,
        view: View,
        plans: list[TilePlan],
        names,
        target: FrameTarget,
        pinned=frozenset(),
        tau: float = DEFAULT_TAU,
    ) -> dict[str, tuple[np.ndarray, float]]:
        """``time_in_frame`` of several strategies, their passes interleaved (``hybrid.oracle.time_in_frames``)."""
        self._check_live()
        return oracle.time_in_frames(self, view, plans, names, target, pinned, tau)

    def render(
        self,
        view: View,
        tau: float = DEFAULT_TAU,
        *,
        measure: bool | None = None,
        maps: bool = False,
        plans: list[TilePlan] | None = None,
        read: bool = True,
        overlay=None,
        **options,
    ) -> RenderResult:
        """Draw the view and read it back: colour, distance (m), FrameStats and the plans drawn; ``plans`` (from
        ``plan`` or an earlier result, choices possibly changed, as calibration does) are drawn instead of the
        view's own, with their choices; ``read=False`` leaves the image on the GPU (colour and distance None), as an
        application's frame loop does; ``overlay(target, view)`` draws into the frame after it is timed (particles).

        With ``measure`` (mixed policies only; the oracle's default when it plans the view itself) every tile is
        also timed inside frames every candidate way (``time_in_frame``) and the oracle takes the cheapest; with
        ``maps`` the result carries the per-pixel strategy map (extra untimed renders). Per-call ``options``
        override the renderer's draw options. An adapting hybrid (``adapt``) learns from the frames it plans
        itself and does not measure (``hybrid.adaptive``).
        """
        self._check_live()
        measure = self._measures(measure, maps, read, plans)
        opts = {n: self.options[n].updated(**o) for n, o in route_options(self.strategies, options).items()}
        own = plans is None  # planned here
        learn = self.online is not None and own and not measure
        plans, plan_ms, prep_ms = self._planned(view, tau, plans)
        explored, adapt_ms = adaptive.timed_explore(self.online, plans, learn)
        pinned = {(p.choice, p.key) for p in plans}
        before = (self.cache.stats.uploads, self.cache.stats.evictions)
        target = FrameTarget(self.ctx, view.width, view.height)
        try:
            together = oracle.measure_plans(self, view, plans, target, pinned, tau) if measure else {}
            motion, self._eye = (None if self._eye is None else view.eye - self._eye), view.eye
            streamed = make_resident(self, plans, pinned, prep_ms, motion)
            predicted, ms = adaptive.timed_prediction(self.model if self.mixed else None, plans)  # before it learns
            adapt_ms += ms if learn else 0.0
            clock = adaptive.PassClock(self.ctx, learn and len({p.choice for p in plans}) > 1)
            counters, draw, gpu, issue = timed_draw(self, target, view, plans, pinned, tau, opts, clock)
            if learn and self.online is not None and not (streamed and streamed.fallback_tiles):
                adapt_ms += adaptive.learn(self.online, clock, plans, draw, gpu, issue, explored, predicted)
            stats = frame_stats(self, plans, plan_ms, draw, gpu, counters, together, predicted)
            stats.choice_reused = own and self.reuse is not None and self.reuse.reused
            add_frame_costs(self, stats, prep_ms, issue, adapt_ms, explored, streamed, before)
            if overlay is not None:
                overlay(target, view)
            return frame_result(self, target, view, plans, stats, counters, tau, opts, read, maps)
        finally:
            target.release()

    def _measures(self, measure: bool | None, maps: bool, read: bool, plans) -> bool:
        """Whether ``render`` times every tile every candidate way (default: a measuring policy planning the view
        itself); refuses arguments that do not go together."""
        if measure and not self.mixed:
            raise TerrabenchError(
                f"measure=True needs a mixed policy ({', '.join(mixed_policies())}), not {self.policy!r}"
            )
        if maps and not read:
            raise TerrabenchError("maps=True reads the frame back; it cannot go with read=False")
        if measure is None:
            return self.entry is not None and self.entry.measures and plans is None
        return bool(measure)

    def _planned(self, view: View, tau: float, plans: list[TilePlan] | None) -> tuple[list[TilePlan], float, float]:
        """(plans, planning ms, one-time preparation ms): the view's own plans unless ``plans`` are given."""
        prep0 = self.triangles.build_ms if self.triangles is not None else 0.0
        t_plan = time.perf_counter()
        plans = self.plan(view, tau) if plans is None else plans
        prep_ms = (self.triangles.build_ms if self.triangles is not None else 0.0) - prep0
        return plans, (time.perf_counter() - t_plan) * 1e3 - prep_ms, prep_ms  # first-seen tiles' work apart

    def strategy_map(
        self, view: View, plans: list[TilePlan], tau: float = DEFAULT_TAU, options: dict | None = None
    ) -> np.ndarray:
        """Per pixel: 0 no terrain, 1 drawn by a raster tile, 2 by a ray-cast tile (compares depth per kind);
        ``options`` are draw options by name over the renderer's, as ``render`` takes them."""
        self._check_live()
        opts = {n: self.options[n].updated(**o) for n, o in route_options(self.strategies, options or {}).items()}
        return strategy_map(self, view, plans, tau, opts)

    def release(self) -> None:
        """Free resident tiles and strategies (and stop the loader of a store pyramid made here); the renderer
        cannot draw afterwards."""
        if self._released:
            return
        self.cache.clear()
        for s in self.strategies.values():
            s.release()
        if self._own_pyramid:
            self.pyramid.close()
        self._released = True


def make_renderer(ctx, hf: HeightField, method: str, tile_size: int = 256, **options):
    """A renderer for a method: the full-resolution reference (options do not apply) or a policy's Renderer."""
    if method == "reference":
        return ReferenceRenderer(ctx, hf)
    return Renderer(ctx, hf, method, tile_size, **options)
