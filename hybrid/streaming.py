"""Making a frame's tiles resident before the renderer draws it: all of them before the timed draw, or within an
upload budget inside the frame, the rest drawn from a resident ancestor (``hybrid.uploads``).

From a tile store the store's loader thread is first asked for the samples the frame lacks (those whose fallback
shows most first, ``hybrid.uploads.fallback_priorities``) with the slow host work of their uploads
(``hybrid.uploads.host_jobs``), then for the triangle estimate's builds, which no upload waits for, and last for
the samples of the tiles one tile ahead of the frame's along the camera's motion (``ahead_keys``: prefetch into
the host cache only, so that no upload is added to a frame); an upload whose host work it has not yet done waits.
"""

from __future__ import annotations

import contextlib
import functools
import math

import numpy as np

from hybrid.tiles.pyramid import TileKey
from hybrid.uploads import UploadReport, fallback_priorities, host_jobs, stream_uploads


def ahead_keys(pyramid, plans: list, motion) -> list[TileKey]:
    """The existing tiles one tile ahead of the plans' tiles, each at its level, along the camera's horizontal
    ``motion`` (world metres since the last frame; a step along an axis that takes at least 0.38 of it), not the
    plans' own; [] where the camera stands still."""
    dx, dy = float(motion[0]), float(motion[1])
    norm = math.hypot(dx, dy)
    if norm == 0.0 or not plans:
        return []
    sx, sy = (int(np.sign(d)) if abs(d) >= 0.38 * norm else 0 for d in (dx, dy))
    keys = np.array([(p.key.level, p.key.tx + sx, p.key.ty + sy) for p in plans], dtype=np.int64)
    own, out = {p.key for p in plans}, dict[TileKey, None]()
    for level in np.unique(keys[:, 0]).tolist():
        at = keys[keys[:, 0] == level]
        for tx, ty in at[pyramid.exists_at(level, at[:, 1], at[:, 2])][:, 1:].tolist():
            key = TileKey(level, tx, ty)
            if key not in own:
                out[key] = None
    return list(out)


def make_resident(r, plans: list, pinned: set, prep_ms: float, motion=None) -> UploadReport | None:
    """Make renderer ``r``'s frame tiles resident: all before the timed draw without an upload budget (None back),
    else within the budget less ``prep_ms`` (the report back; ``r._fallbacks`` maps the tiles left to ancestors).
    ``motion``: the eye's move since the last frame (world metres), along which a store's loader reads ahead."""
    r._fallbacks = {}
    if r.upload_budget_ms is None:
        for p in plans:  # upload first: the timed frame measures drawing only
            r._resident(p.choice, p.key, pinned)
        return None
    ready, deferred, priority = (lambda key: True), (lambda plan: False), None
    pyramid = r.pyramid
    if pyramid.background_loader:  # a store: its loader thread reads what is missing, most visible first
        missing = [p for p in plans if (p.choice, p.key) not in r.cache.entries]
        rank = fallback_priorities(r.cache, missing, pyramid.max_level, pyramid.error)
        priority = {(p.choice, p.key): v for p, v in zip(missing, rank)}  # the jobs' order too
        missing = [missing[i] for i in sorted(range(len(missing)), key=lambda i: -rank[i])]
        work, waiting = host_jobs(r.strategies, missing, pyramid.n, pyramid)
        later = {k: [fn] for k, fn in (getattr(r.triangles, "waiting", None) or {}).items()}  # no upload waits
        if motion is not None:  # last: the samples of the tiles the camera is moving towards
            ahead = [k for k in ahead_keys(pyramid, plans, motion) if k not in later]
            cached = pyramid.cached_keys(ahead)
            later.update({k: [functools.partial(pyramid.samples, k)] for k in ahead if k not in cached})
        pyramid.request([p.key for p in missing] + list(work), work, later)
        ready = pyramid.cached_keys([p.key for p in missing]).__contains__  # one look, not one a tile
        deferred = lambda p: (p.choice, p.key) in waiting and not pyramid.failed(p.key)  # noqa: E731
    # the frame's budget covers the estimate's preparation and the uploads together; a store's loader waits
    with pyramid.held() if pyramid.background_loader else contextlib.nullcontext():
        streamed = _stream(r, plans, pinned, prep_ms, ready, deferred, priority)
    r._fallbacks = {plans[i].key: a for i, a in streamed.fallbacks.items()}
    return streamed


def _stream(r, plans, pinned, prep_ms, ready, deferred, priority) -> UploadReport:
    """``stream_uploads`` with the renderer's cache, strategies, tiles, budget, errors and job costs."""
    return stream_uploads(
        r.cache,
        r.strategies,
        plans,
        pinned,
        r.tile,
        r.pyramid.max_level,
        max(r.upload_budget_ms - prep_ms, 0.0),
        ready,
        deferred,
        r.pyramid.error,
        r.job_costs,
        priority,
    )
