"""Timing tiles inside real frames, one call each, every candidate way: the oracle's measurements and calibration's.

Functions of a ``hybrid.renderer.Renderer`` (its strategies, resident tiles and draw options); the renderer's
``time_draw``, ``time_in_frame`` and ``time_in_frames`` call them.
"""

from __future__ import annotations

import numpy as np

from hybrid.camera.view import View
from hybrid.contract import TileItem
from hybrid.cost.choice import best_assignment
from hybrid.cost.fit import estimate_overhead
from hybrid.gl.target import FrameTarget
from hybrid.gl.timing import timed
from hybrid.strategies import candidates


def timed_call(r, target: FrameTarget, view: View, name: str, items: list[TileItem], tau: float) -> float:
    """ms of one draw call of ``items`` with strategy ``name`` of renderer ``r`` into the target as it stands: the
    GL timer query on real GPUs, the wall clock around ctx.finish() on CPU rasterizers."""
    _, wall, gpu, _ = timed(
        r.ctx, lambda: r.strategies[name].draw_tiles(target, view, items, tau, **r.options[name].values())
    )
    return wall if gpu is None else gpu


def time_draw(r, view: View, plans, name: str, target: FrameTarget, pinned, tau: float) -> float:
    """Median ms over ``r.oracle_repeats`` of drawing the plans' tiles with one strategy in one call."""
    items = r._items(name, plans, pinned)
    times = []
    for _ in range(r.oracle_repeats):
        target.clear()
        target.use()
        times.append(timed_call(r, target, view, name, items, tau))
    return float(np.median(times))


def time_in_frames(r, view: View, plans, names, target: FrameTarget, pinned, tau: float) -> dict:
    """{strategy: (per-tile ms (B,), whole-frame ms)}: every plan's tile drawn with each strategy inside a real
    frame, front to back, each in its own call (so each meets the depth its nearer tiles left), and the same frame
    in one call; medians over ``r.oracle_repeats``, the strategies' passes interleaved so that a drift of the
    machine's speed falls on all of them alike."""
    items = {n: r._items(n, plans, pinned) for n in names}
    per = {n: np.empty((r.oracle_repeats, len(items[n]))) for n in names}
    together: dict = {n: [] for n in names}
    for k in range(r.oracle_repeats):
        for n in names:
            target.clear()
            target.use()
            per[n][k] = [timed_call(r, target, view, n, [item], tau) for item in items[n]]
    for _ in range(r.oracle_repeats):
        for n in names:
            target.clear()
            target.use()
            together[n].append(timed_call(r, target, view, n, items[n], tau))
    return {n: (np.median(per[n], axis=0), float(np.median(together[n]))) for n in names}


def measure_plans(r, view: View, plans, target: FrameTarget, pinned: set, tau: float) -> dict:
    """Time every tile inside frames each candidate way (each plan's ``measured``) and each pure frame (returned,
    ms by strategy); the oracle policy then takes the cheapest assignment, with per-strategy overheads estimated
    from the same frames."""
    pinned |= {(n, p.key) for p in plans for n in candidates()}
    if not plans:
        return {}
    runs = time_in_frames(r, view, plans, candidates(), target, pinned, tau)
    per, together = {n: t[0] for n, t in runs.items()}, {n: t[1] for n, t in runs.items()}
    for i, p in enumerate(plans):
        p.measured = {n: float(per[n][i]) for n in candidates()}
    if r.policy == "oracle":
        overhead = {n: estimate_overhead([per[n]], [together[n]]) for n in candidates()}
        best, _ = best_assignment({n: per[n] - overhead[n] for n in candidates()}, overhead, together)
        for p, c in zip(plans, best):
            p.choice = c
    return together
