"""Timing a draw: wall clock around ctx.finish() everywhere, and a GL timer query on real GPUs.

On Mesa's CPU rasterizers GL timer queries are wrong (they see only part of the work), so there the wall
clock is the only measure; on a GPU the timer query gives the GPU's own elapsed time as well. The issue time is
the CPU's share: the wall clock until the drawing function returns, less what it waited inside for the GL
(``gl_finish``, as before a read of counters, and on a CPU rasterizer ``gl_memory_barrier``, where it finishes
the queued work); on llvmpipe it still includes the vertex, geometry and compute work, which run inside the
draw and dispatch calls, but not rasterization and fragment work, which run at the waits.
"""

from __future__ import annotations

import time

from hybrid.gl.context import context_extra, gl_finish, gl_waited_ms, is_software


def timer_queries_valid(ctx) -> bool:
    """True where GL timer queries can be trusted (not llvmpipe/softpipe); cached on the context."""
    extra = context_extra(ctx)
    if "timer_queries" not in extra:
        extra["timer_queries"] = not is_software(ctx)
    return extra["timer_queries"]


def timed(ctx, fn, query: bool = True):
    """(fn(), wall ms, GPU ms or None, issue ms): fn runs between two ctx.finish(); GPU ms from a timer query on
    GPUs (not with ``query`` False: fn times its own parts, and GL time queries do not nest); issue ms the wall
    clock until fn returns less its waits for the GL."""
    timer = ctx.query(time=True) if query and timer_queries_valid(ctx) else None
    ctx.finish()
    waited = gl_waited_ms()
    t0 = time.perf_counter()
    if timer is not None:
        with timer:
            out = fn()
    else:
        out = fn()
    issue = (time.perf_counter() - t0) * 1e3 - (gl_waited_ms() - waited)
    gl_finish(ctx)  # other threads (the tile loader) run while the GL works
    wall = (time.perf_counter() - t0) * 1e3
    gpu = None
    if timer is not None:
        gpu = timer.elapsed / 1e6  # moderngl frees a query with its Python object
    return out, wall, gpu, issue
