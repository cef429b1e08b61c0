"""The scaling experiment of Dick et al. (Figs. 9-10): one camera path, scaled to each terrain's extent, over
tile stores of growing size; per frame the wall time, uploads, fallback tiles, GPU bytes and host memory.

    terrabench scale STORE [STORE ...] [--frames 48] [--methods raycast,raster,raster_gs,hybrid]

Every method draws the flight once per store, the stores interleaved frame by frame (a drift of the machine
falls on every size alike), streaming: uploads are jobs inside each frame within ``upload_budget_ms``
(tiles still waiting are drawn from a resident ancestor), resident tiles within a GPU byte budget, tile
samples read from disk on demand within a host byte budget. A frame is drawn once (a repeat would find the
queue drained), so the per-frame times carry the machine's noise: the tables give medians and 99th
percentiles over a flight, and the ray caster's size ratio is read against the spread of its own frames.
Host memory is the process's resident set (``/proc/self/statm``) after each frame, with every store of the method
open (an upper bound of one store's), and each store's host cache (tiles and decoded chunks). A method that cannot draw a
store (the raster strategies on a store prepared without node arrays, or on a large periodic extension of one)
is recorded with the reason.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from experiments.frozen import frozen_heap

if TYPE_CHECKING:
    from hybrid.terrain.stored import StoredTerrain

METHODS = ("raycast", "raster", "raster_gs", "hybrid")


def rss_bytes() -> int:
    """This process's resident set size in bytes (Linux), 0 where unknown."""
    try:
        return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def overview(terrain, width: int, height: int):
    """A view from 20 terrain sizes straight above the centre: the whole terrain in a few pixels (the root tile)."""
    from hybrid.camera.view import View

    w, d = terrain.extent
    ox, oy, oz = terrain.origin
    c = np.array([ox + w / 2, oy + d / 2, oz])
    size = max(w, d)
    return View(c + np.array([0.0, -0.01 * size, 20.0 * size]), c, 40, width, height, near=size, far=40.0 * size)


def warm_up(r, view, tau: float) -> None:
    """Draw the view (the root tile) with each of the renderer's strategies, skirts included (and, for a mixed
    policy, the ray caster stopping at an earlier pass's depth, a program of its own), so that the driver compiles
    their shaders before the flight's first frame."""
    from hybrid.gl.target import FrameTarget

    plans = r.plan(view, tau)
    target = FrameTarget(r.ctx, view.width, view.height)
    try:
        for name, strategy in r.strategies.items():
            r.time_draw(view, plans, name, target, tau=tau)
            if "skirts" in strategy.draw_options:  # and the skirt programs of mixed frames
                strategy.draw_tiles(target, view, r._items(name, plans, set()), tau, skirts={p.key: 15 for p in plans})
                strategy.draw_skirts(target, view)
            if r.mixed and "occluders" in strategy.draw_options:
                strategy.draw_tiles(target, view, r._items(name, plans, set()), tau, occluders=True)
    finally:
        target.release()


@dataclass
class _Flight:
    """One store's flight for one method: its terrain, views, pyramid and renderer (GPU state)."""

    terrain: StoredTerrain
    views: list
    pyramid: Any = None
    renderer: Any = None

    def close(self) -> None:
        """Release the renderer and stop the pyramid's loader thread (freeing its host cache)."""
        if self.renderer is not None:
            self.renderer.release()
            self.renderer = None
        if self.pyramid is not None:
            self.pyramid.close()
            self.pyramid = None


def run_scaling(
    ctx,
    stores,
    frames: int = 48,
    size=(640, 360),
    tau: float = 2 / 3,
    methods=METHODS,
    gpu_budget_mib: int = 256,
    upload_budget_ms: float | None = 8.0,
    host_budget_mib: int = 512,
    flight: str = "transect",
) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """(frames, refusals, setup) tables of every method over every store (paths), one pass each (streaming within
    ``upload_budget_ms``, or with None each frame's tiles uploaded before it, untimed); setup
    is the one-off time before the first frame (the root tile of each strategy, with the raster strategies'
    node data, read from the store: a periodic extension's from its source's, window by window; and one frame of
    the root alone, in which the driver compiles the shaders).

    A method's flights over the stores are timed interleaved, frame k of every store before frame k + 1 (the
    first store rotating), so a drift of the machine over the run falls on every size alike and the size ratios
    compare frames drawn at the same time; while a store's frame is timed the other stores' loader threads are
    held, so that none reads in the background of another's frame. Host RSS is the process's, with every store
    of the method open."""
    from hybrid.camera.flight import preset
    from hybrid.tiles.periodic import open_any_store

    rows: list[dict] = []  # a frame's measures each
    refused: list[dict] = []  # a store and method that refused, with the reason
    setup: list[dict] = []  # a store and method's one-off setup
    flights = []
    for path in stores:
        terrain = open_any_store(path)
        flights.append(_Flight(terrain, preset(flight, terrain, frames, *size).views()))
    for method in methods:
        live = [
            f
            for f in flights
            if _open(ctx, f, method, tau, size, gpu_budget_mib, upload_budget_ms, host_budget_mib, refused, setup)
        ]
        try:
            with frozen_heap():  # no full collection inside the frames
                for k in range(frames):
                    turn = [f for f in live if f.renderer is not None]
                    shift = k % max(len(turn), 1)
                    for f in turn[shift:] + turn[:shift]:
                        for g in turn:  # only this store's loader reads while its frame is timed
                            if g.pyramid is not None:
                                g.pyramid.pause(g is not f)
                        _frame(f, method, k, tau, gpu_budget_mib, rows, refused)
        finally:
            for f in flights:
                f.close()
    return (
        pd.DataFrame(rows),
        pd.DataFrame(refused, columns=["store", "samples", "method", "reason"]),
        pd.DataFrame(setup, columns=["store", "samples", "method", "setup_s"]),
    )


def _open(
    ctx,
    f: _Flight,
    method: str,
    tau: float,
    size,
    gpu_budget_mib: int,
    upload_budget_ms,
    host_budget_mib: int,
    refused: list,
    setup: list,
) -> bool:
    """Make f's pyramid and renderer for the method and time its setup; False (the reason recorded) if refused."""
    from hybrid.errors import StoreDamagedError, TerrabenchError
    from hybrid.renderer import Renderer
    from hybrid.tiles.store import StorePyramid

    t = f.terrain
    samples = t.rows * t.cols
    f.pyramid = StorePyramid(t, host_bytes=host_budget_mib << 20)
    try:
        f.renderer = r = Renderer(
            ctx,
            t,
            method,
            int(t.store.attrs["tile_size"]),
            pyramid=f.pyramid,
            budget_bytes=gpu_budget_mib << 20,
            upload_budget_ms=upload_budget_ms,
        )
        t0 = time.perf_counter()  # one-off setup (the root tile's upload): not a frame
        for name in r.strategies:
            r.cache.get(name, r.strategies[name], f.pyramid.root(), lambda: f.pyramid.tile(f.pyramid.root()))
        warm_up(r, overview(t, *size), tau)
        setup.append({"store": t.name, "samples": samples, "method": method, "setup_s": time.perf_counter() - t0})
        return True
    except TerrabenchError as exc:
        f.close()
        if isinstance(exc, StoreDamagedError):  # a damaged store is the input's fault, not a refusal
            raise
        refused.append({"store": t.name, "samples": samples, "method": method, "reason": str(exc)})
        return False


def _frame(f: _Flight, method: str, k: int, tau: float, gpu_budget_mib: int, rows: list, refused: list) -> None:
    """Draw frame k of f's flight and append its row; a refusal mid-flight drops the store's rows for the method."""
    from hybrid.errors import StoreDamagedError, TerrabenchError

    t = f.terrain
    t0 = time.perf_counter()
    try:
        st = f.renderer.render(f.views[k], tau).stats
    except TerrabenchError as exc:
        if isinstance(exc, StoreDamagedError):
            raise
        refused.append({"store": t.name, "samples": t.rows * t.cols, "method": method, "reason": str(exc)})
        rows[:] = [x for x in rows if not (x["store"] == t.name and x["method"] == method)]
        f.close()
        return
    rows.append(
        {
            "store": t.name,
            "samples": t.rows * t.cols,
            "side": t.cols,
            "periodic": bool(t.store.attrs.get("periodic")),
            "method": method,
            "frame": k,
            "wall_ms": st.wall_ms,
            "draw_ms": st.draw_ms,
            "plan_ms": st.plan_ms,
            "upload_ms": st.upload_ms,
            "uploads": st.uploads,
            "fallback_tiles": st.fallback_tiles,
            "pending_uploads": st.pending_uploads,
            "tiles": st.tiles,
            "gpu_bytes": st.gpu_bytes,
            "resident_bytes": st.gpu_bytes - st.shared_bytes,
            "prep_ms": st.prep_ms,
            "gpu_budget": gpu_budget_mib << 20,
            "host_cache_bytes": f.pyramid.cache_bytes,
            "host_rss": rss_bytes(),
            "call_ms": (time.perf_counter() - t0) * 1e3,
        }
    )


def summary(frames: pd.DataFrame) -> pd.DataFrame:
    """Per store and method: median and p99 frame time, their ratio, fallback frames, peak GPU bytes (all, and the
    resident tiles' that the budget bounds) and host bytes."""
    g = frames.groupby(["side", "store", "method"], sort=True)
    out = g.agg(
        frames=("wall_ms", "size"),
        median_ms=("wall_ms", "median"),
        p99_ms=("wall_ms", lambda x: float(np.percentile(x, 99))),
        spread_iqr_ms=("wall_ms", lambda x: float(np.percentile(x, 75) - np.percentile(x, 25))),
        uploads=("uploads", "sum"),
        fallback_frames=("fallback_tiles", lambda x: int((x > 0).sum())),
        peak_gpu_mib=("gpu_bytes", lambda x: x.max() / 2**20),
        peak_resident_mib=("resident_bytes", lambda x: x.max() / 2**20),
        gpu_budget_mib=("gpu_budget", lambda x: x.max() / 2**20),
        peak_host_rss_mib=("host_rss", lambda x: x.max() / 2**20),
        peak_host_cache_mib=("host_cache_bytes", lambda x: x.max() / 2**20),
    ).reset_index()
    out["p99_over_median"] = out["p99_ms"] / out["median_ms"]
    return out


def size_ratio(frames: pd.DataFrame, method: str = "raycast") -> dict | None:
    """The method's median frame time on the largest store over that on the smallest, with a bootstrap interval
    over frames (the noise of the same run); None without two stores."""
    f = frames[frames["method"] == method]
    sides = sorted(f["side"].unique())
    if len(sides) < 2:
        return None
    a = f[f["side"] == sides[-1]]["wall_ms"].to_numpy()
    b = f[f["side"] == sides[0]]["wall_ms"].to_numpy()
    rng = np.random.default_rng(0)
    boot = [np.median(rng.choice(a, len(a))) / np.median(rng.choice(b, len(b))) for _ in range(2000)]
    return {
        "large": int(sides[-1]),
        "small": int(sides[0]),
        "ratio": float(np.median(a) / np.median(b)),
        "low": float(np.percentile(boot, 2.5)),
        "high": float(np.percentile(boot, 97.5)),
    }
