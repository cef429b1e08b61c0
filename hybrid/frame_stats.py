"""A drawn frame's FrameStats: times, tiles by strategy, GPU bytes by strategy kind, and the frame's other costs.

Functions of a ``hybrid.renderer.Renderer`` (its residency cache, strategies and cost model).
"""

from __future__ import annotations

from hybrid.contract import FrameStats


def gpu_bytes_by_kind(r) -> tuple[dict[str, int], int]:
    """({kind: GPU bytes}, shared bytes): renderer ``r``'s resident tiles and its strategies' shared objects."""
    by_kind = {"raster": 0, "raycast": 0}
    for (name, _), g in r.cache.entries.items():
        by_kind[r.kind(name)] += int(g.nbytes)
    shared = 0
    for name, s in r.strategies.items():
        b = int(s.shared_nbytes)
        by_kind[r.kind(name)] += b
        shared += b
    return by_kind, shared


def frame_stats(r, plans, plan_ms, draw, gpu, counters, together, pred: float | None) -> FrameStats:
    """The FrameStats of renderer ``r``'s frame of ``plans``: times, tiles, GPU bytes and ``pred``, the model's
    prediction of the frame made before the frame was drawn (None: not mixed, or not known)."""
    by_kind, shared = gpu_bytes_by_kind(r)
    n_raster = sum(r.kind(p.choice) == "raster" for p in plans)
    return FrameStats(
        wall_ms=plan_ms + draw,
        plan_ms=plan_ms,
        draw_ms=draw,
        gpu_ms=gpu,
        tiles=len(plans),
        tiles_raster=n_raster,
        tiles_raycast=len(plans) - n_raster,
        tiles_gs=sum(p.choice == "raster_gs" for p in plans),
        gpu_bytes=by_kind["raster"] + by_kind["raycast"],
        gpu_bytes_raster=by_kind["raster"],
        gpu_bytes_raycast=by_kind["raycast"],
        shared_bytes=shared,
        pred_ms=pred,
        counters=counters,
        together_ms=together,
        plans=list(plans) if r.mixed else [],
    )


def add_frame_costs(
    r, stats: FrameStats, prep_ms: float, issue: float, adapt_ms: float, explored, streamed, before: tuple[int, int]
) -> None:
    """Fill in the frame's preparation, issue, adaptation, streaming and residency figures (renderer ``r``'s
    uploads and evictions since ``before``)."""
    stats.prep_ms, stats.issue_ms, stats.adapt_ms = prep_ms, issue, adapt_ms
    stats.explored_tiles = 0 if explored is None else len(explored.tiles)
    stats.wall_ms += adapt_ms
    if streamed is not None:
        stats.upload_ms, stats.fallback_tiles, stats.pending_uploads = (
            streamed.upload_ms,
            streamed.fallback_tiles,
            streamed.fallback_tiles,
        )
        stats.wall_ms += streamed.upload_ms + prep_ms
    stats.uploads = r.cache.stats.uploads - before[0]
    stats.evictions = r.cache.stats.evictions - before[1]
