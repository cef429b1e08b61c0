"""Uploads as jobs under a per-frame time budget, and fallback tiles drawn from a resident coarser ancestor.

Bhattacharjee et al. (§4.3) keep a frame's GPU work bounded by queueing what a new view needs (uploads, max-mip
builds, per-tile buffers) and running only as much of it as fits in the frame; a tile whose data is not yet on
the GPU is drawn from its resident ancestor meanwhile, so the frame never shows a hole. Here one job is one
``strategy.upload(tile)`` (which includes the strategy's per-tile GPU builds). Each frame runs the jobs that fit
in ``budget_ms`` of wall time (at least one job a frame, so the queue always drains; after it, a job starts only
if its expected time, ``JobCosts``, fits in what is left): first those whose CPU tile the ``ready`` callback says is
loaded (a tile store's loader thread reads ahead), then the others, whose job reads the tile as well, each group
by priority, the tile whose fallback shows the largest screen-space error first (``fallback_priorities``), except
those ``deferred`` to the loader thread: jobs whose slow CPU part
(``host_jobs``: a periodic extension's node block cut near a seam, tens to hundreds of ms) it runs first, so that
no frame waits for it. The coarsest tile (the root) of every
strategy in use is made resident before anything else, whatever the budget, so every tile has an ancestor.

A fallback draws the ancestor's GPU data clipped to the missing tile's rectangle, without stitching to its
neighbours (a coarser surface for a few frames, never a hole).
"""

from __future__ import annotations

import statistics
import time
from collections import deque
from dataclasses import dataclass, field, replace
from functools import partial

from hybrid.errors import TerrabenchError
from hybrid.residency import BudgetExceeded
from hybrid.tiles.pyramid import TileKey
from hybrid.tiles.tiletree import NO_NEIGHBOUR


@dataclass
class UploadReport:
    """One frame's streaming: jobs run, their wall ms, jobs left waiting, and tiles drawn from an ancestor."""

    uploads: int = 0
    upload_ms: float = 0.0
    fallbacks: dict = field(default_factory=dict)

    @property
    def fallback_tiles(self) -> int:
        """Tiles drawn from an ancestor this frame: every job still waiting is one."""
        return len(self.fallbacks)


def fallback_selection(sel, key: TileKey):
    """The selection record of a missing tile redirected to its ancestor ``key``: no neighbour to stitch to."""
    return sel._replace(key=key, coarser_edges=0, edge_deltas=(NO_NEIGHBOUR,) * 4)


def fallback_tile(ancestor_tile, clip, zrange=None):
    """The ancestor's CPU tile restricted to the missing tile's world rectangle ``clip`` (x0, y0, x1, y1) and, with
    ``zrange``, to the missing tile's height bounds (world metres): they bound the ancestor's ray-cast surface
    there too, a union of the ancestor's cells whose corners are samples of the missing tile. (Not for a raster
    tile: its leaves reach past the rectangle, so its surface inside may not lie within them.)"""
    out = replace(ancestor_tile, clip=tuple(float(c) for c in clip))
    return out if zrange is None else replace(out, zmin=float(zrange[0]), zmax=float(zrange[1]))


def host_jobs(strategies: dict, plans, n: int, pyramid=None) -> tuple[dict, set]:
    """A frame's host work for a store's loader thread: (key -> callables, the (choice, key) uploads waiting for
    it). ``plans`` are the tiles whose upload is missing; strategies with a ``host_work(key, n)`` (the raster
    ones) give theirs, which their upload waits for. With the store's ``pyramid``, a strategy with a
    ``host_prepare(heights, source_step, key)`` (the ray caster's codes, the raster strategies' node blocks) has
    it made for the tile (``StorePyramid.derive``) so that its upload is mostly the GL's part; an upload does not
    wait for that (it prepares its tile itself)."""
    work: dict = {}
    waiting = set()
    for p in plans:
        fn = getattr(strategies[p.choice], "host_work", None)
        job = fn(p.key, n) if fn is not None else None
        if job is not None:
            work.setdefault(p.key, []).append(job)
            waiting.add((p.choice, p.key))
    for name in {p.choice for p in plans} if pyramid is not None else ():
        prepare = getattr(strategies[name], "host_prepare", None)
        if prepare is None:
            continue
        product = strategies[name].host_product
        keys = [p.key for p in plans if p.choice == name]
        made = pyramid.derived_keys(keys, product)
        for k in keys:
            if k not in made:
                work.setdefault(k, []).append(partial(pyramid.derive, k, product, partial(prepare, key=k)))
    return work, waiting


class JobCosts:
    """Expected wall ms of an upload job by (strategy, whether its samples were loaded): the median of the last
    ``keep`` jobs of its kind (a median, so that one job slowed by the machine's other work does not hold back
    the next frames' jobs), so that a frame starts only the jobs that fit in what is left of its budget."""

    def __init__(self, keep: int = 8):
        self.keep, self.ms = int(keep), dict[tuple, deque]()
        self._median: dict[tuple, float] = {}  # by kind, updated as jobs are recorded (read once a job)

    def expect(self, kind) -> float:
        """The expected ms of a job of this kind (0 before any was run: the first one measures it)."""
        return self._median.get(kind, 0.0)

    def record(self, kind, ms: float) -> None:
        """Take in the wall ms of a job just run."""
        times = self.ms.setdefault(kind, deque(maxlen=self.keep))
        times.append(float(ms))
        self._median[kind] = float(statistics.median(times))  # (as np.median, without its per-call overhead)


def nearest_ancestors(cache, plans, max_level: int) -> list[TileKey]:
    """Per plan, the nearest ancestor of its tile resident for its strategy (the root if none is). Tiles share
    ancestors: each (strategy, tile)'s nearest resident one is found once."""
    root, out = TileKey(max_level, 0, 0), []
    nearest: dict[tuple, TileKey] = {}  # (strategy, tile) -> its nearest resident ancestor
    for p in plans:
        walked, k, anc = [], p.key, root
        while k.level < max_level:
            k = k.parent()
            if (p.choice, k) in nearest:
                anc = nearest[(p.choice, k)]
                break
            walked.append((p.choice, k))
            if (p.choice, k) in cache.entries:
                anc = k
                break
        nearest.update(dict.fromkeys(walked, anc))
        out.append(anc)
    return out


def fallback_priorities(cache, plans, max_level: int, error_of) -> list[float]:
    """Per plan, how much its fallback shows: the nearest resident ancestor's geometric error (the root's if none
    is yet) over the tile's distance (proportional to that error in pixels; infinite with the eye in its box)."""
    errors: dict[TileKey, float] = {}
    out = []
    for p, anc in zip(plans, nearest_ancestors(cache, plans, max_level)):
        if anc not in errors:
            errors[anc] = float(error_of(anc))
        distance = float(p.selected.distance)
        out.append(errors[anc] / distance if distance > 0 else float("inf"))
    return out


def job_order(
    cache, plans, missing: list, ready, max_level: int, error_of, priority: dict | None = None
) -> list[tuple[int, bool]]:
    """The frame's jobs as (plan index, samples loaded): loaded ones first (their job is the GPU's part), each group
    by priority (``fallback_priorities``, largest first, or ``priority`` by (strategy, key) when the frame has
    them already; front to back without either)."""
    loaded = {i: bool(ready(plans[i].key)) for i in missing}
    rank = dict.fromkeys(missing, 0.0)
    if priority is not None:
        rank = {i: -priority.get((plans[i].choice, plans[i].key), 0.0) for i in missing}
    elif error_of is not None:
        rank = dict(
            zip(missing, (-v for v in fallback_priorities(cache, [plans[i] for i in missing], max_level, error_of)))
        )
    return sorted(((i, loaded[i]) for i in missing), key=lambda j: (not j[1], rank[j[0]], j[0]))


def stream_uploads(
    cache,
    strategies: dict,
    plans,
    pinned: set,
    make_tile,
    max_level: int,
    budget_ms: float,
    ready=lambda key: True,
    deferred=lambda plan: False,
    error_of=None,
    costs: JobCosts | None = None,
    priority: dict | None = None,
) -> UploadReport:
    """Run a frame's upload jobs within ``budget_ms`` and pick an ancestor for every tile still missing.

    ``plans`` (front to back) carry ``key``, ``choice`` and ``selected``; ``pinned`` gains every (strategy, key) the
    frame draws, ancestors included. Jobs run in ``job_order`` (by priority with ``error_of(key)``, a tile's
    geometric error, or ``priority``); after the first, a job starts only if its expected ms (``costs``) fits in
    what is left. Returns the report; ``fallbacks`` maps a plan index to its ancestor's key.
    """
    if not (budget_ms >= 0):
        raise TerrabenchError(f"upload budget must be >= 0 ms a frame, got {budget_ms!r}")
    report, costs = UploadReport(), costs or JobCosts()
    root = TileKey(max_level, 0, 0)
    t0 = time.perf_counter()
    for name in sorted({p.choice for p in plans}):
        if (name, root) not in cache.entries:  # every tile's last resort: always resident
            cache.get(name, strategies[name], root, lambda: make_tile(root), pinned | {(name, root)})
            report.uploads += 1
        pinned.add((name, root))
    missing = [i for i, p in enumerate(plans) if (p.choice, p.key) not in cache.entries]
    waiting = {i for i in missing if deferred(plans[i])}  # the loader thread's first: not this frame
    now = [i for i in missing if i not in waiting]
    full: set = set()  # kinds of job that no longer fit in what is left of the budget
    for i, loaded in job_order(cache, plans, now, ready, max_level, error_of, priority):
        p, kind = plans[i], (plans[i].choice, loaded)
        if kind in full:
            continue
        spent = (time.perf_counter() - t0) * 1e3
        if report.uploads and spent >= budget_ms:
            break
        if report.uploads and spent + costs.expect(kind) > budget_ms:
            full.add(kind)  # would not end within the budget (a cheaper kind further on may)
            continue
        try:
            start = time.perf_counter()
            cache.get(p.choice, strategies[p.choice], p.key, lambda p=p: make_tile(p.key), pinned)
            costs.record(kind, (time.perf_counter() - start) * 1e3)
            report.uploads += 1
        except BudgetExceeded:
            continue  # no room this frame: drawn from its ancestor
    report.upload_ms = (time.perf_counter() - t0) * 1e3
    left = [i for i in missing if (plans[i].choice, plans[i].key) not in cache.entries]
    for i, anc in zip(left, nearest_ancestors(cache, [plans[i] for i in left], max_level)):
        pinned.add((plans[i].choice, anc))
        report.fallbacks[i] = anc
    return report
