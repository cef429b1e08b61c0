"""Planning benchmark: CPU milliseconds per frame of ``plan_frame``, per-tile features against the batch, in one run.

    python -m experiments.bench_planning [--frames 8] [--size 640x360] [--repeats 7]

No GL: tile selection, the raster strategy's triangle estimate, features, predicted costs and the hybrid
choice on Puget's flyover and orbit flights with the cost model calibrated on llvmpipe. Per tile size and
tau, the median over repeats of each frame's time, then the median over frames: the whole plan computed
tile by tile (``batch=False``) and as arrays, and the parts (selection, triangles, features) alone; what the
hybrid adds to the selection every policy pays (features, predictions, choices) is the batch plan less the
selection, the two timed back to back in each of 3x the repeats and the median of their differences taken.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pandas as pd

LLVMPIPE = "llvmpipe (LLVM 15.0.6, 256 bits)"


def _median_ms(fn, repeats: int) -> float:
    """Median wall milliseconds of repeated calls."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def _paired_ms(fn, base, repeats: int) -> float:
    """Median over repeats of fn's wall ms less base's, the two timed back to back in each repeat (so a drift of
    the machine falls on both)."""
    diffs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        t1 = time.perf_counter()
        base()
        diffs.append((t1 - t0) - (time.perf_counter() - t1))
    return 1e3 * float(np.median(diffs))


def run_benchmark(hf, flights: dict, model, tile_sizes=(256, 128), taus=(2 / 3,), repeats: int = 7) -> pd.DataFrame:
    """One row per (flight, tile size, tau, frame): tiles and median ms of each planning step."""
    from hybrid.cost.features import feature_columns, tile_features
    from hybrid.cost.planner import default_estimator, plan_frame
    from hybrid.tiles.pyramid import TilePyramid
    from hybrid.tiles.tiletree import select_tiles

    def frame_ms(pyramid, est, view, tau) -> dict:
        """Median ms of each planning step for one view (the timed lambdas bind this call's arguments)."""
        sel = select_tiles(pyramid, view, tau)
        tri, vis = est.many(sel, view, tau)  # warm: per-tile node data
        return {
            "tiles": len(sel),
            "plan per tile ms": _median_ms(lambda: plan_frame(pyramid, view, model, batch=False), repeats),
            "plan batch ms": _median_ms(lambda: plan_frame(pyramid, view, model), repeats),
            "select ms": _median_ms(lambda: select_tiles(pyramid, view, tau), repeats),
            "triangles ms": _median_ms(lambda: est.many(sel, view, tau), repeats),
            "features per tile ms": _median_ms(
                lambda: [tile_features(pyramid, view, s, t, v) for s, t, v in zip(sel, tri, vis)], repeats
            ),
            "features batch ms": _median_ms(lambda: feature_columns(pyramid, view, sel, tri, vis), repeats),
            "features + choices ms (target <= 0.5)": _paired_ms(
                lambda: plan_frame(pyramid, view, model), lambda: select_tiles(pyramid, view, tau), 3 * repeats
            ),
        }

    rows = []
    for size in tile_sizes:
        pyramid = TilePyramid(hf, size)
        est = default_estimator(pyramid)
        for fname, views in flights.items():
            for tau in taus:
                for k, view in enumerate(views):
                    rows.append(
                        {
                            "flight": fname,
                            "tile_size": size,
                            "tau": tau,
                            "frame": k,
                            **frame_ms(pyramid, est, view, tau),
                        }
                    )
    return pd.DataFrame(rows)


def summarize(df: pd.DataFrame) -> pd.DataFrame:
    """Per flight, tile size and tau: median ms per frame of each step, and the batch's speed-ups."""
    cols = [c for c in df.columns if " ms" in c]
    out = df.groupby(["flight", "tile_size", "tau"], sort=False)[["tiles"] + cols].median()
    out["plan speed-up"] = out["plan per tile ms"] / out["plan batch ms"]
    out["features speed-up"] = out["features per tile ms"] / out["features batch ms"]
    # the machine's speed drifts between runs and sessions; the share of the selection (the same code every
    # policy runs, timed in the same repeats) compares across them
    out["features + choices / select"] = out["features + choices ms (target <= 0.5)"] / out["select ms"]
    return out.reset_index()


def run(
    ctx=None,
    frames: int = 8,
    size: str = "640x360",
    taus=(2 / 3,),
    tile_sizes=(256, 128),
    repeats: int = 7,
    flights=("flyover", "orbit"),
) -> dict[str, pd.DataFrame]:
    """The benchmark on Puget, its table keyed by title; ``ctx`` is unused (planning needs no GL)."""
    from hybrid.camera.flight import preset
    from hybrid.camera.view import parse_size
    from hybrid.cost.model import load_cost_model
    from hybrid.terrain.datasets import puget

    w, h = parse_size(size, "size")
    hf = puget()
    views = {f: preset(f, hf, frames, w, h).views() for f in flights}
    model = load_cost_model(LLVMPIPE)
    title = (
        f"planning on {hf.name} at {w}x{h}, {frames} frames a flight, CPU only, median of {repeats} "
        f"(cost model {model.source})"
    )
    return {title: summarize(run_benchmark(hf, views, model, tile_sizes, taus, repeats))}


def main(argv=None) -> int:
    """Run the planning benchmark on Puget and print its table."""
    from .tables import text_tables

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--size", default="640x360")
    ap.add_argument("--repeats", type=int, default=7)
    a = ap.parse_args(argv)
    print(text_tables(run(None, a.frames, a.size, repeats=a.repeats)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
