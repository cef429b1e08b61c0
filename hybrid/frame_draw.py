"""Drawing a frame's passes: each strategy's tiles in one call, raster kinds first, then skirts; timed.

Functions of a ``hybrid.renderer.Renderer`` (its strategies, resident tiles and draw options): ``Renderer.render``
draws every frame through ``timed_draw``.
"""

from __future__ import annotations

import numpy as np

from hybrid import adaptive
from hybrid.cost.planner import TilePlan
from hybrid.gl.timing import timed


def draw_frame(
    r, target, view, plans: list[TilePlan], pinned, tau: float, options: dict, clock: adaptive.PassClock | None = None
) -> dict:
    """Draw renderer ``r``'s plans into the bound target, a pass per strategy (skirts last), with each strategy's
    draw options (``options``, by name); the counters summed."""
    counters: dict = {}
    skirts = r.skirts(plans)
    kinds = [r.kind(p.choice) for p in plans]
    # rays can pass behind raster tiles only where one of those lies nearer (earlier front to back)
    behind = (
        "raster" in kinds
        and "raycast" in kinds
        and kinds.index("raster") < len(kinds) - 1 - kinds[::-1].index("raycast")
    )
    rasterized = False
    for name in r._order():
        sub = [p for p in plans if p.choice == name]
        if not sub:
            continue
        opts = options[name].values()
        if skirts and "skirts" in r.strategies[name].draw_options:
            opts["skirts"] = skirts
        if behind and rasterized and "occluders" in opts and opts["occluders"] is None:
            opts["occluders"] = True  # rays stop behind the raster tiles drawn before them
        rasterized |= r.kind(name) == "raster"
        items = r._items(name, sub, pinned)
        c = (
            run_pass(
                clock,
                name,
                lambda name=name, items=items, opts=opts: r.strategies[name].draw_tiles(
                    target, view, items, tau, **opts
                ),
            )
            or {}
        )
        for k, v in c.items():
            if isinstance(v, (int, float, np.integer, np.floating)):
                counters[k] = counters.get(k, 0) + v
    if skirts:  # last, so the ray caster's pre-pass sees no skirt inside a ray-cast tile's box
        for name in r._order():
            if "skirts" in r.strategies[name].draw_options and any(p.choice == name for p in plans):
                run_pass(clock, adaptive.SKIRTS, lambda name=name: r.strategies[name].draw_skirts(target, view))
    return counters


def run_pass(clock, name: str, fn):
    """fn() timed as a pass by the frame's clock, where there is one."""
    return fn() if clock is None else clock.run(name, fn)


def timed_draw(r, target, view, plans, pinned, tau: float, opts: dict, clock) -> tuple:
    """(counters, draw ms, GPU ms or None, issue ms) of drawing renderer ``r``'s frame into the cleared target."""
    target.clear()
    target.use()
    try:
        counters, draw, gpu, issue = timed(
            r.ctx, lambda: draw_frame(r, target, view, plans, pinned, tau, opts, clock), query=not clock.gpu
        )
    finally:
        r._fallbacks = {}
    return counters, draw, clock.gpu_ms if clock.gpu else gpu, issue
