"""Hybrid benchmark: raster, raycast, heuristic, hybrid and oracle over the same flights, in one run.

    python -m experiments.bench_hybrid [--frames 8] [--size 640x360] [--tau 0.6667] [--flights flyover,orbit]

Prints, per flight, total and median per-frame wall time (ctx.finish() around each frame, median of
repeats) of every policy, the ratios it targets (hybrid vs the better pure method, hybrid vs the
oracle), and the cost model's per-tile median absolute relative error against the oracle's measurements.
"""
from __future__ import annotations

import argparse

import numpy as np
import pandas as pd

POLICIES = ("raster", "raycast", "heuristic", "hybrid", "oracle")


def run_benchmark(ctx, hf, flights: dict, tau: float = 2 / 3, repeats: int = 3, tile_size: int = 256) -> tuple:
    """(frames table, per-tile table): wall ms per policy and frame; predicted vs measured per tile."""
    from hybrid.renderer import make_renderer
    rows, tiles = [], []
    for fname, views in flights.items():
        for pol in POLICIES:
            r = make_renderer(ctx, hf, pol, tile_size=tile_size)
            try:
                r.render(views[0], tau)                      # warm: uploads, shader compiles
                for k, v in enumerate(views):
                    res = [r.render(v, tau) for _ in range(repeats)]
                    st = res[-1].stats
                    rows.append({"flight": fname, "policy": pol, "frame": k,
                                 "wall_ms": float(np.median([x.stats.wall_ms for x in res])),
                                 "tiles": st.tiles, "tiles_raster": st.tiles_raster, "tiles_raycast": st.tiles_raycast,
                                 "pred_ms": np.nan if st.pred_ms is None else st.pred_ms})
                    if pol == "oracle":
                        for t in st.tile_rows:
                            tiles.append({"flight": fname, "frame": k, **t})
            finally:
                r.release()
    return pd.DataFrame(rows), pd.DataFrame(tiles)


def summarize(frames: pd.DataFrame, tiles: pd.DataFrame, model) -> dict[str, pd.DataFrame]:
    """The benchmark tables keyed by title: per flight and policy, the ratios, and the cost model's error."""
    out, ratios = {}, []
    for fname, g in frames.groupby("flight", sort=False):
        t = g.groupby("policy", sort=False).agg(total_ms=("wall_ms", "sum"), median_ms=("wall_ms", "median"),
                                                raster_tiles=("tiles_raster", "sum"),
                                                raycast_tiles=("tiles_raycast", "sum"))
        out[f"flight {fname} ({g['frame'].nunique()} frames)"] = t.reset_index()
        tot = t["total_ms"]
        best = min(("raster", "raycast"), key=lambda p: tot[p])
        ratios.append({"flight": fname, "better pure": best, "hybrid speed-up vs better pure": tot[best] / tot["hybrid"],
                       "hybrid / oracle": tot["hybrid"] / tot["oracle"]})
    out["hybrid against the better pure method (target > 1) and the oracle (target <= 1.15)"] = pd.DataFrame(ratios)
    if len(tiles):
        err = []
        for s in ("raster", "raycast"):
            pred = tiles[f"pred_{s}_ms"] + model.overhead.get(s, 0.0)
            meas = tiles[f"meas_{s}_ms"]
            err.append({"strategy": s, "median |relative error| %": 100 * float(np.median(np.abs(pred - meas) / meas)),
                        "tiles": len(tiles)})
        err.append({"strategy": "both", "median |relative error| %":
                    float(np.median([e["median |relative error| %"] for e in err])), "tiles": len(tiles)})
        out[f"cost model ({model.source}): per-tile error against the oracle's measurements (target <= 20 %)"] = \
            pd.DataFrame(err)
    return out


def run(ctx, frames: int = 8, size: str = "640x360", tau: float = 2 / 3, repeats: int = 3,
        flights=("flyover", "orbit")) -> dict[str, pd.DataFrame]:
    """The benchmark on Puget: its tables keyed by title; size WIDTHxHEIGHT in pixels, tau in pixels."""
    from hybrid.camera.flight import preset
    from hybrid.camera.view import parse_size
    from hybrid.cost.model import load_cost_model
    from hybrid.gl.context import gl_info
    from hybrid.terrain.datasets import puget
    w, h = parse_size(size, "size")
    hf = puget()
    views = {f: preset(f, hf, frames, w, h).views() for f in flights}
    model = load_cost_model(gl_info(ctx).renderer)
    frames_df, tiles = run_benchmark(ctx, hf, views, tau, repeats)
    return summarize(frames_df, tiles, model)


def main(argv=None) -> int:
    """Run the hybrid benchmark on Puget and print its tables."""
    from hybrid.gl.context import gl_info, shared_context

    from .tables import text_tables
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--size", default="640x360")
    ap.add_argument("--tau", type=float, default=2 / 3)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--flights", default="flyover,orbit")
    a = ap.parse_args(argv)
    ctx = shared_context()
    print(f"device: {gl_info(ctx).renderer}")
    print(text_tables(run(ctx, a.frames, a.size, a.tau, a.repeats, a.flights.split(","))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
