"""Benchmark of issue 5: raster, raycast, heuristic, hybrid and oracle over the same flights, in one run.

    python -m experiments.bench_hybrid [--frames 8] [--size 640x360] [--tau 0.6667] [--flights flyover,orbit]

Prints, per flight, total and median per-frame wall time (ctx.finish() around each frame, median of
repeats) of every policy, the ratios the issue targets (hybrid vs the better pure method, hybrid vs the
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


def summarize(frames: pd.DataFrame, tiles: pd.DataFrame, model) -> str:
    """The benchmark tables as text."""
    out = []
    for fname, g in frames.groupby("flight", sort=False):
        t = g.groupby("policy", sort=False).agg(total_ms=("wall_ms", "sum"), median_ms=("wall_ms", "median"),
                                                raster_tiles=("tiles_raster", "sum"),
                                                raycast_tiles=("tiles_raycast", "sum"))
        out.append(f"flight {fname} ({g['frame'].nunique()} frames)\n" + t.to_string(float_format=lambda v: f"{v:.1f}"))
        tot = t["total_ms"]
        best = min(("raster", "raycast"), key=lambda p: tot[p])
        out.append(f"  hybrid vs better pure ({best}): {tot[best] / tot['hybrid']:.2f}x "
                   f"(target > 1);  hybrid / oracle: {tot['hybrid'] / tot['oracle']:.2f} (target <= 1.15)")
    if len(tiles):
        err = []
        for s in ("raster", "raycast"):
            pred = tiles[f"pred_{s}_ms"] + model.overhead.get(s, 0.0)
            meas = tiles[f"meas_{s}_ms"]
            e = float(np.median(np.abs(pred - meas) / meas))
            err.append(e)
            out.append(f"cost model, {s}: per-tile median |relative error| {100 * e:.1f} % over {len(tiles)} tiles")
        out.append(f"cost model, both: {100 * float(np.median(err)):.1f} % (target <= 20 %)")
    return "\n".join(out)


def main(argv=None) -> int:
    """Run the hybrid benchmark on Puget and print its tables."""
    from hybrid.cost.model import load_cost_model
    from hybrid.terrain.datasets import puget
    from hybrid.camera.flight import preset
    from hybrid.gl.context import gl_info, shared_context
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--size", default="640x360")
    ap.add_argument("--tau", type=float, default=2 / 3)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--flights", default="flyover,orbit")
    a = ap.parse_args(argv)
    w, h = (int(x) for x in a.size.split("x"))
    ctx = shared_context()
    hf = puget()
    flights = {f: preset(f, hf, a.frames, w, h).views() for f in a.flights.split(",")}
    model = load_cost_model(gl_info(ctx).renderer)
    print(f"device: {gl_info(ctx).renderer}; cost model: {model.source}")
    frames, tiles = run_benchmark(ctx, hf, flights, a.tau, a.repeats)
    print(summarize(frames, tiles, model))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
