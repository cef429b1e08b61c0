"""A drawn frame read back: colour, distance and stats with its plans, and the per-pixel strategy map.

Functions of a ``hybrid.renderer.Renderer`` (its strategies, resident tiles and draw options).
"""

from __future__ import annotations

import numpy as np

from hybrid.camera.view import View
from hybrid.cost.planner import TilePlan
from hybrid.gl.target import FrameTarget, RenderResult

STRATEGY_CODES = {"raster": 1, "raycast": 2}
"""Per-pixel codes of the strategy map, by strategy kind (0 = no terrain)."""


def frame_result(r, target, view, plans, stats, counters, tau, opts, read: bool, maps: bool) -> RenderResult:
    """The frame read back (or left on the GPU with ``read`` False), with its plans and, with ``maps``, renderer
    ``r``'s strategy map."""
    if not read:
        return RenderResult(None, None, stats, plans=plans)
    result = target.read(view, stats)
    result.plans = plans
    if "triangles" in counters:  # drawn triangles per pixel that shows terrain
        counters["triangles_per_pixel"] = counters["triangles"] / max(int(result.mask.sum()), 1)
    if maps:
        result.maps = {"strategy": strategy_map(r, view, plans, tau, opts)}
    return result


def strategy_map(r, view: View, plans: list[TilePlan], tau: float, options: dict) -> np.ndarray:
    """Per pixel: 0 no terrain, 1 drawn by a raster tile, 2 by a ray-cast tile (compares depth per kind): each of
    renderer ``r``'s strategies draws its plans alone, with its draw options (``options`` by name) but without
    pre-pass, into a target of its own."""
    depths = {}
    for name in r.strategies:
        sub = [p for p in plans if p.choice == name]
        t = FrameTarget(r.ctx, view.width, view.height)
        try:
            t.clear()
            t.use()
            if sub:
                opts = options[name].values()
                if "prepass" in opts:
                    opts["prepass"] = False
                r.strategies[name].draw_tiles(t, view, r._items(name, sub, set()), tau, **opts)
            depths[name] = t.read_depth()
        finally:
            t.release()
    out = np.zeros((view.height, view.width), np.uint8)
    best = np.zeros((view.height, view.width), np.float32)
    for name in r._order():  # raster kinds first: they win ties, as in the frame
        d = depths[name]
        win = (d > 0) & (d > best) if r.kind(name) == "raycast" else (d > 0) & (d >= best)
        out[win] = STRATEGY_CODES[r.kind(name)]
        best = np.where(win, d, best)
    return out
