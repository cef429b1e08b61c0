"""Ray-caster benchmark: naive stepping vs max mipmap vs max mipmap + tile-ID pre-pass vs float32 tiles.

Renders the frames of a flight with hybrid.renderer.Renderer('raycast') and reports, per
configuration, rays/s, mean steps per ray and ms/frame; 'maxmip float32' casts tiles of float32 metres, the
baseline that measures what the 16-bit codes cost. Times are wall clock around ctx.finish() of the
draw calls plus tile selection (uploads and read-back excluded), from a pass with statistics off; ray
and step counts come from a second pass with statistics on (exact). On llvmpipe timings are noisy.

    python -m experiments.bench_raycast [--frames 8] [--width 640] [--height 360] [--dataset puget]
"""

from __future__ import annotations

import argparse

import pandas as pd

CONFIGS = {
    "naive": dict(traversal="naive", prepass=False),
    "maxmip": dict(traversal="maxmip", prepass=False),
    "maxmip+prepass": dict(traversal="maxmip", prepass=True),
    "maxmip float32": dict(traversal="maxmip", prepass=False, heights="float32"),
}


def run_benchmark(
    ctx, hf, views, configs: dict | None = None, tau: float = 2.0 / 3.0, mode: str = "shaded", tile_size: int = 256
) -> pd.DataFrame:
    """One row per (configuration, frame): wall ms, rays started, hits, steps, capped, tiles; for the views.

    Every configuration draws each frame before the next frame is drawn, so a change of the machine's speed
    reaches all of them alike; configurations with another tile format (``heights``) have their own renderer."""
    from hybrid.renderer import Renderer

    configs = configs or CONFIGS
    rows = []
    renderers: dict = {}
    try:
        for opts in configs.values():
            fmt = opts.get("heights", "uint16")
            if fmt not in renderers:
                renderers[fmt] = Renderer(ctx, hf, "raycast", tile_size=tile_size, heights=fmt)
            for stats in (False, True):  # warm-up: compile, upload
                renderers[fmt].render(views[0], tau, mode=mode, stats=stats, **opts)
        for k, view in enumerate(views):
            for name, opts in configs.items():
                r = renderers[opts.get("heights", "uint16")]
                timed = r.render(view, tau, mode=mode, stats=False, **opts)
                counted = r.render(view, tau, mode=mode, stats=True, **opts)
                rows.append(_row(name, k, view, timed, counted))
    finally:
        for r in renderers.values():
            r.release()
    return pd.DataFrame(rows)


def _row(name: str, k: int, view, timed, counted) -> dict:
    """One (configuration, frame) row from the frame drawn with statistics off (timed) and on (counted)."""
    s = counted.stats.row()
    return {
        "config": name,
        "frame": k,
        "wall_ms": timed.stats.wall_ms,
        "wall_ms_stats": s["wall_ms"],
        "tiles": s["tiles"],
        "rays": s["rays"],
        "hits": s["hits"],
        "steps": s["steps"],
        "max_steps": s["max_steps"],
        "capped": s["capped"],
        "pixels": view.width * view.height,
        "coverage": float(counted.mask.mean()),
    }


def summarize(df: pd.DataFrame) -> pd.DataFrame:
    """Per configuration: ms/frame, rays/s (started rays), mean steps/ray, pixels/s, speed-ups, and the median
    and quartiles over frames of each frame's time over the same frame's max-mipmap time."""
    g = df.groupby("config", sort=False)
    out = pd.DataFrame(
        {
            "ms/frame": g["wall_ms"].mean(),
            "M rays/s": g["rays"].sum() / (g["wall_ms"].sum() / 1e3) / 1e6,
            "M pixels/s": g["pixels"].sum() / (g["wall_ms"].sum() / 1e3) / 1e6,
            "rays/frame": g["rays"].mean(),
            "steps/ray": g["steps"].sum() / g["rays"].sum(),
            "max steps": g["max_steps"].max(),
            "capped": g["capped"].sum(),
            "tiles/frame": g["tiles"].mean(),
            "coverage": g["coverage"].mean(),
            "ms/frame (stats on)": g["wall_ms_stats"].mean(),
        }
    )
    base = out["ms/frame"].get("naive")
    if base is not None:
        out["speed-up vs naive"] = base / out["ms/frame"]
    if "maxmip" in out.index:
        ref = df[df["config"] == "maxmip"].set_index("frame")["wall_ms"]
        ratio = df["wall_ms"] / df["frame"].map(ref)
        q = ratio.groupby(df["config"], sort=False).quantile([0.25, 0.5, 0.75]).unstack()
        out["time / maxmip (median)"] = q[0.5]
        out["time / maxmip (q1-q3)"] = [f"{a:.3f}-{b:.3f}" for a, b in zip(q[0.25], q[0.75])]
    return out


def measure(
    ctx,
    frames: int = 8,
    dataset: str = "puget",
    flight: str = "flyover",
    width: int = 640,
    height: int = 360,
    tau: float = 2.0 / 3.0,
) -> tuple[str, pd.DataFrame]:
    """(title, per-frame rows) of the benchmark on a dataset's flight; tau in pixels, sizes in pixels."""
    from hybrid.camera.flight import preset
    from hybrid.terrain.datasets import get_dataset

    hf = get_dataset(dataset)
    views = preset(flight, hf, frames=frames, width=width, height=height).views()
    title = (
        f"ray caster on {hf.name} {hf.cols}x{hf.rows}, {flight} flight, {frames} frames at {width}x{height}, "
        f"tau {tau:.3g} px"
    )
    return title, run_benchmark(ctx, hf, views, tau=tau)


def run(ctx, frames: int = 8, **options) -> dict[str, pd.DataFrame]:
    """The summary table per configuration, keyed by its title; options as for measure()."""
    title, df = measure(ctx, frames, **options)
    return {title: summarize(df).reset_index()}


def main(argv=None) -> int:
    """Run the benchmark on a dataset's flight and print the table."""
    from hybrid.gl.context import gl_info, shared_context

    from .tables import text_tables

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dataset", default="puget")
    p.add_argument("--flight", default="flyover")
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=360)
    p.add_argument("--tau", type=float, default=2.0 / 3.0)
    p.add_argument("--csv", default=None, help="also write the per-frame rows to this CSV file")
    a = p.parse_args(argv)
    ctx = shared_context()
    title, df = measure(ctx, a.frames, a.dataset, a.flight, a.width, a.height, a.tau)
    if a.csv:
        df.to_csv(a.csv, index=False)
    print(f"GL {gl_info(ctx).renderer}")
    print(text_tables({title: summarize(df).reset_index()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
