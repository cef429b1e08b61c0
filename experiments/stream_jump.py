"""Streaming after a camera jump: per frame, the share of drawn tiles at their wanted level (not drawn from an
ancestor), and how many frames it takes to reach a share.

    from experiments.stream_jump import jump_frames, frames_to
    rows = jump_frames(ctx, "store@periodic262145", "raycast")
    frames_to(rows, 0.95)

The camera sits at the start of the transect flight (``hybrid.camera.flight``) with every tile it wants resident,
then jumps to the flight's end (40 % of the terrain's diagonal away: no tile of the new view is resident) and
stays there; every frame after the jump is drawn once, streaming within the upload budget, as the scaling
experiment draws its frames. ``moving`` frames after the jump go on along the flight's direction instead, a
step a frame, so that prefetch along the motion has something to predict.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from experiments.frozen import frozen_heap

WANTED = 0.95  # the share of tiles at their wanted level the streaming target asks for


def jump_views(terrain, frames: int, size=(640, 360), moving: bool = False) -> tuple:
    """(the view before the jump, the views of ``frames`` frames after it) over the terrain's transect."""
    from hybrid.camera.flight import preset

    before, after = preset("transect", terrain, 2, *size).views()
    if not moving:
        return before, [after] * frames
    step = 0.01  # of the jump's length a frame
    views = []
    for k in range(frames):
        shift = (after.eye - before.eye) * step * k
        views.append(_moved(after, shift))
    return before, views


def _moved(view, shift: np.ndarray):
    """The view with its eye and target moved by ``shift`` (world metres)."""
    from dataclasses import replace

    return replace(view, eye=view.eye + shift, target=view.target + shift)


def jump_frames(
    ctx,
    store,
    method: str = "raycast",
    frames: int = 40,
    size=(640, 360),
    tau: float = 2 / 3,
    upload_budget_ms: float = 8.0,
    gpu_budget_mib: int = 256,
    host_budget_mib: int = 512,
    moving: bool = False,
    settle: bool = False,
) -> pd.DataFrame:
    """One row per frame after the jump (frame 1 first): tiles, those at their wanted level and their share,
    uploads, upload ms, frame wall ms; ``store`` is a path or STORE@periodicSIZE. With ``settle`` each frame
    starts once the loader thread has done what the last one asked (counts then do not depend on the machine)."""
    from hybrid.renderer import Renderer
    from hybrid.tiles.periodic import open_any_store
    from hybrid.tiles.store import StorePyramid

    terrain = open_any_store(store)
    before, views = jump_views(terrain, frames, size, moving)
    pyramid = StorePyramid(terrain, host_bytes=host_budget_mib << 20)
    n = int(terrain.store.attrs["tile_size"])
    with Renderer(
        ctx,
        terrain,
        method,
        n,
        pyramid=pyramid,
        budget_bytes=gpu_budget_mib << 20,
        upload_budget_ms=1e9,
        adapt=False,
    ) as r:
        _settled(r, pyramid, before, tau)
        r.upload_budget_ms = upload_budget_ms
        rows = []
        with frozen_heap():  # no full collection inside the frames
            for k, v in enumerate(views):
                if settle:
                    pyramid.idle(60)
                rows.append(_frame_row(r, k + 1, v, tau))
    pyramid.close()
    out = pd.DataFrame(rows)
    out.insert(0, "method", method)
    out.insert(0, "store", terrain.name)
    return out


def _settled(r, pyramid, view, tau: float, tries: int = 8) -> None:
    """Draw the view until every tile it wants is resident (uploads the loader thread's host work held back
    drawn again once it is done), shaders compiled and the loader idle: nothing of it left for the jump."""
    for _ in range(tries):
        if r.render(view, tau, read=False).stats.fallback_tiles == 0 and pyramid.idle(60):
            return
        pyramid.idle(60)


def _frame_row(r, k: int, view, tau: float) -> dict:
    """Draw one frame and return its row."""
    t0 = time.perf_counter()
    st = r.render(view, tau, read=False).stats
    at = st.tiles - st.fallback_tiles
    return {
        "frame": k,
        "tiles": st.tiles,
        "at_wanted": at,
        "share": at / max(st.tiles, 1),
        "uploads": st.uploads,
        "upload_ms": st.upload_ms,
        "wall_ms": st.wall_ms,
        "call_ms": (time.perf_counter() - t0) * 1e3,
    }


def frames_to(rows: pd.DataFrame, share: float = WANTED) -> int | None:
    """The first frame after the jump (1 = the jump's own) whose share of tiles at their wanted level reaches
    ``share`` and stays there, or None if it never does within the rows."""
    below = np.flatnonzero(rows["share"].to_numpy() < share)
    if len(below) == len(rows):
        return None
    last = int(below[-1]) + 1 if len(below) else 0
    return int(rows["frame"].iloc[last]) if last < len(rows) else None


def jump_summary(rows: pd.DataFrame, share: float = WANTED) -> dict:
    """Frames to ``share``, the share at frame 30, uploads a frame, upload ms a frame (median and max), and the
    frames' wall ms (median, p99) of one jump's rows."""
    at30 = rows[rows["frame"] <= 30]["share"]
    return {
        "frames_to_share": frames_to(rows, share),
        "share_at_30": float(at30.iloc[-1]) if len(at30) else float("nan"),
        "uploads_mean": float(rows["uploads"].mean()),
        "upload_ms_median": float(rows["upload_ms"].median()),
        "upload_ms_max": float(rows["upload_ms"].max()),
        "wall_ms_median": float(rows["wall_ms"].median()),
        "wall_ms_p99": float(np.percentile(rows["wall_ms"], 99)),
    }


def run_jumps(ctx, stores, methods, frames: int = 40, size=(640, 360), tau: float = 2 / 3, **budgets) -> pd.DataFrame:
    """``jump_frames`` of every method over every store, one after another (rows of all); ``budgets`` are
    ``jump_frames``' budget arguments. A method a store refuses (``TerrabenchError``) is left out."""
    from hybrid.errors import StoreDamagedError, TerrabenchError

    out = []
    for store in stores:
        for method in methods:
            try:
                out.append(jump_frames(ctx, store, method, frames, size, tau, **budgets))
            except StoreDamagedError:
                raise
            except TerrabenchError:
                continue  # the scaling run records the reason
    return pd.concat(out, ignore_index=True) if out else pd.DataFrame()


def jump_table(rows: pd.DataFrame, share: float = WANTED) -> pd.DataFrame:
    """``jump_summary`` per store and method of ``run_jumps``' rows."""
    return pd.DataFrame(
        [{"store": s, "method": m, **jump_summary(g, share)} for (s, m), g in rows.groupby(["store", "method"])]
    )
