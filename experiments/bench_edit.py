"""Edit benchmark: what one edit costs each strategy as the terrain grows.

    python -m experiments.bench_edit [--sizes 1025,4097,8193,16385] [--methods raycast,raster] [--edits 8]

Puget tiled to larger grids (its 1024² cells repeated, so that one brush meets the same relief at every size;
from 16385² the GPU heights are held in blocks, ``hybrid.gl.brush``), a camera above the grid's centre at
640x360, tiles of 256, one 2 km crater an edit along a short path, and a frame drawn between edits, as in a run:
its caches are what the next edit meets. Per size and method: the median ms of each update step and of the whole
update over the edits after the first two; the first edit apart (it makes the pyramid's deviation blocks and the
raster nodes' edit state, one pass over the grid); the frame; and the update against the smallest terrain's.
Then as many edits back to back, with no frame between, along a path of their own: the same work with the CPU's
caches warm, which tells the edit's own growth with the terrain from what a frame leaves cold. Then as many again,
each after a pause of ``PAUSE_S`` with nothing drawn: on a shared machine work that follows a long frame finds its
memory gone from the caches, whatever the frame drew (a probe of a quarter millisecond takes five times as long
after 180 ms asleep as back to back), and a larger grid's frame is longer; after the same pause every size meets
the same cold caches.
Target: the same brush costs within 1.3x on the larger grids.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pandas as pd

SIZES = (1025, 4097, 8193)
METHODS = ("raycast", "raster")
TARGET = "update / smallest (target <= 1.3)"
PAUSE_S = 0.2  # the pause before each edit of the third series: longer than a 16385² frame here


def tiled_puget(size: int):
    """Puget's 1024² cells repeated to a (size, size) grid (size - 1 a multiple of 1024), on its source step."""
    from hybrid.terrain.datasets import puget
    from hybrid.terrain.heightfield import HeightField

    base = puget(with_texture=False)
    reps = (size - 1) // 1024
    h = np.pad(np.tile(base.heights[:-1, :-1], (reps, reps)), ((0, 1), (0, 1)), mode="edge")
    spacing = (base.spacing_x, base.spacing_y)
    return HeightField(h.astype(np.float32), spacing, name=f"puget-tiled-{size}", source_step=base.source_step)


def measure(ctx, size: int, method: str, edits: int) -> dict:
    """One row: per-step median ms over the edits after the first two, the first edit's ms, the frame's ms."""
    from hybrid.camera.view import View
    from hybrid.editing import TerrainEditor
    from hybrid.renderer import Renderer
    from hybrid.terrain.edits import Crater

    hf = tiled_puget(size)
    t0 = time.perf_counter()
    cx, cy = 0.5 * (hf.cols - 1) * hf.spacing_x, 0.5 * (hf.rows - 1) * hf.spacing_y
    view = View(np.array([cx - 3000.0, cy - 3000.0, 6000.0]), np.array([cx, cy, 1000.0]), width=640, height=360)
    steps: dict[str, list[float]] = {}
    frames, refreshed = [], []
    with Renderer(ctx, hf, method, 256, reuse_choice=1) as r, TerrainEditor(ctx, hf, r) as editor:
        r.render(view, 2 / 3, read=False)
        setup = time.perf_counter() - t0
        for k in range(edits):
            rep = editor.apply(Crater((cx + 500.0 * k, cy + 300.0 * k), 2000.0, 300.0))
            steps.setdefault("total", []).append(sum(rep.ms.values()))
            for s, ms in rep.ms.items():
                steps.setdefault(s, []).append(ms)
            refreshed.append(sum(rep.refreshed.values()))
            frames.append(r.render(view, 2 / 3, read=False).stats.wall_ms)
        warm = [sum(editor.apply(Crater((cx - 400.0 * k, cy), 2000.0, 300.0)).ms.values()) for k in range(edits)]
        paused = [_after_pause(editor, Crater((cx, cy - 400.0 * k), 2000.0, 300.0)) for k in range(edits)]
    row = {"size": size, "method": method, "setup s": setup, "first edit ms": steps["total"][0]}
    row.update({f"{s} ms": float(np.median(v[2:])) for s, v in steps.items() if s != "total"})
    row.update({"update ms": float(np.median(steps["total"][2:])), "refreshed tiles": float(np.median(refreshed))})
    row["frame ms"] = float(np.median(frames[2:]))
    row["back to back ms"] = float(np.median(warm[2:]))
    row["after a pause ms"] = float(np.median(paused[2:]))
    return row


def _after_pause(editor, brush) -> float:
    """The update ms of one edit applied after ``PAUSE_S`` with nothing drawn."""
    time.sleep(PAUSE_S)
    return sum(editor.apply(brush).ms.values())


def run(ctx, sizes=SIZES, methods=METHODS, edits: int = 8) -> dict[str, pd.DataFrame]:
    """The benchmark's table: a row per (method, size), its update against the smallest size's."""
    rows = [measure(ctx, s, m, edits) for m in methods for s in sizes]
    df = pd.DataFrame(rows)
    smallest = df.groupby("method")["update ms"].transform("first")
    df.insert(df.columns.get_loc("update ms") + 1, TARGET, df["update ms"] / smallest)
    df["share of frame"] = df["update ms"] / df["frame ms"]
    for col, name in (("back to back ms", "back to back / smallest"), ("after a pause ms", "after a pause / smallest")):
        df[name] = df[col] / df.groupby("method")[col].transform("first")
    title = (
        f"one 2 km crater an edit on Puget tiled to larger grids (640x360, tiles of 256, median of {edits - 2} edits "
        "after two, a frame between edits)"
    )
    return {title: df}


def main(argv=None) -> int:
    """Run the edit benchmark and print its table."""
    from hybrid.gl.context import gl_info, shared_context

    from .tables import text_tables

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default=",".join(map(str, SIZES)))
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--edits", type=int, default=8)
    a = ap.parse_args(argv)
    sizes = [int(s) for s in a.sizes.split(",") if s.strip().isdigit()]
    if not sizes or any(s < 1025 or (s - 1) % 1024 or s > 16385 for s in sizes):
        ap.error(f"--sizes must be grid sizes 1024 k + 1 up to 16385, got {a.sizes!r}")
    methods = a.methods.split(",")
    if not set(methods) <= {"raycast", "raster", "raster_gs", "hybrid"} or a.edits < 3:
        ap.error(f"--methods must name raycast, raster, raster_gs or hybrid and --edits be >= 3, got {a.methods!r}")
    ctx = shared_context()
    print(f"device: {gl_info(ctx).renderer}")
    print(text_tables(run(ctx, sizes, methods, a.edits)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
