"""Adaptation benchmark: the hybrid started from wrong cost models, against the pure methods, over Puget's flights.

    python -m experiments.bench_adapt [--frames 24] [--size 640x360] [--repeats 3]

Starts: another device's model (the shipped H200 model, saved under this GL renderer's key in a costs file and
loaded from it as a user's file would be), the shipped uncalibrated fallback, this device's model with every
ray-casting coefficient and its per-frame overhead divided by 5 (a badly wrong prior), and this device's own
model. This device's model is the one shipped for its GL renderer, never the user's costs file, so that the
benchmark does not depend on what earlier runs learned. Each start is drawn adapting (the default) and frozen (the starting gap), beside raster, raster_gs and
ray casting, per flight and tau, every frame by every renderer in turn, the flight ``repeats`` times, each time from a cold
adapting hybrid (it sees every view once, as a user's run does). The targets read frames 8 to the end: the
adapting hybrid's median frame within 1.05x of the better pure method's, and within noise of the hybrid
started from this device's model (``experiments.noise.compare``).
"""

from __future__ import annotations

import argparse
import copy
import json
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from hybrid.strategies import candidates

STARTS = ("h200", "fallback", "skewed", "device")
SETTLED_FROM = 8
TARGET = "adapting / better pure, frames 8- (target <= 1.05)"
FLOOR = "better pure drawn again / itself (the floor)"


def start_models(renderer: str) -> dict:
    """The starting cost models by name (``STARTS``) for a GL renderer."""
    from hybrid.cost.model import _shipped, fallback_cost_model, load_cost_model, shipped_cost_model

    device = shipped_cost_model(renderer)
    skewed = copy.deepcopy(device)
    skewed.coefficients["raycast"] = {k: v / 5 for k, v in skewed.coefficients["raycast"].items()}
    skewed.overhead = {**skewed.overhead, "raycast": skewed.overhead["raycast"] / 5}
    skewed.source = f"{device.source}, ray casting / 5"
    h200 = {**_shipped()["NVIDIA H200"], "renderer": renderer}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "costs.json"
        path.write_text(json.dumps({renderer: h200}))
        other = load_cost_model(renderer, path)
    other.source = "shipped 'NVIDIA H200' under this renderer's key"
    return {"h200": other, "fallback": fallback_cost_model(), "skewed": skewed, "device": device}


def again(policy: str) -> str:
    """The name of a pure method's second renderer, drawn like the first: the ratio of the two is what a hybrid
    that drew exactly as the better pure method would read against it (the floor of the benchmark's noise)."""
    return f"{policy} (again)"


def draw_flight(ctx, hf, views, tau: float, models: dict, repeats: int, tile_size: int) -> pd.DataFrame:
    """Rows (method, frame, wall_ms, wall_ms_repeats, pred_ms, draw_ms, tiles by kind, explored tiles): the flight
    drawn ``repeats`` times, every view by every renderer in turn; methods are the pure policies and, per start
    model, ``hybrid:<start>`` adapting and ``frozen:<start>``. Each repeat's adapting hybrids start cold from their
    model, as a user's run does: they see every view once."""
    from hybrid.renderer import Renderer

    fixed: dict[str, tuple[str, dict]] = {p: (p, {}) for p in candidates()}
    fixed.update({again(p): (p, {}) for p in candidates()})  # each pure method twice: the target's noise floor
    for name, model in models.items():
        fixed[f"frozen:{name}"] = ("hybrid", {"cost_model": model, "adapt": False})
    cold = {f"hybrid:{name}": ("hybrid", {"cost_model": model}) for name, model in models.items()}
    names = list(fixed) + list(cold)
    stats: dict = {(m, k): [] for m in names for k in range(len(views))}
    renderers: dict = {}
    try:
        for rep in range(repeats):
            for m, (policy, kw) in {**(fixed if rep == 0 else {}), **cold}.items():
                if m in renderers:
                    renderers[m].release()
                renderers[m] = Renderer(ctx, hf, policy, tile_size, **kw)
                renderers[m].render(views[0], tau, read=False)  # warm, as a run's configuration is: compiles, uploads
            for k, v in enumerate(views):
                shift = (k * repeats + rep) % len(names)  # every renderer in turn, the first one rotating
                for m in names[shift:] + names[:shift]:
                    stats[(m, k)].append(renderers[m].render(v, tau, read=False).stats)
    finally:
        for r in renderers.values():
            r.release()
    return pd.DataFrame([frame_row(m, k, st) for (m, k), st in stats.items()])


def frame_row(method: str, frame: int, st: list) -> dict:
    """One row of ``draw_flight``: a method's frame over the repeats (the median wall ms, the last repeat's rest)."""
    w = [s.wall_ms for s in st]
    return {
        "method": method,
        "frame": frame,
        "wall_ms": float(np.median(w)),
        "wall_ms_repeats": w,
        "pred_ms": st[-1].pred_ms,
        "draw_ms": st[-1].draw_ms,
        "plan_ms": st[-1].plan_ms,
        "adapt_ms": st[-1].adapt_ms,
        "tiles_raster": st[-1].tiles_raster,
        "tiles_raycast": st[-1].tiles_raycast,
        "explored": sum(s.explored_tiles for s in st),
    }


def summarize(frames: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """The benchmark's tables: per flight, tau and start model the targets' ratios and readings, and the per-frame
    median ms of every method."""
    from .adapt_charts import prediction_error
    from .noise import compare

    rows = []
    for (flight, tau), g in frames.groupby(["flight", "tau"], sort=False):
        late = g[g["frame"] >= SETTLED_FROM]
        by = {m: q for m, q in late.groupby("method", sort=False)}
        pure_ms = {p: float(by[p]["wall_ms"].median()) for p in candidates()}
        best = min(pure_ms, key=lambda p: pure_ms[p])
        for s in sorted({m.split(":")[1] for m in by if ":" in m}, key=STARTS.index):
            hy, fr = by[f"hybrid:{s}"], by[f"frozen:{s}"]
            rows.append(
                {
                    "flight": flight,
                    "tau": tau,
                    "start": s,
                    "better pure": best,
                    "better pure ms": pure_ms[best],
                    "adapting ms": float(hy["wall_ms"].median()),
                    TARGET: float(hy["wall_ms"].median()) / pure_ms[best],
                    "frozen / better pure (starting gap)": float(fr["wall_ms"].median()) / pure_ms[best],
                    FLOOR: float(by[again(best)]["wall_ms"].median()) / pure_ms[best],
                    "adapting against better pure": compare("hybrid", hy, best, by[best]).words(),
                    "adapting against the device's start": compare("hybrid", hy, "device", by["hybrid:device"]).words(),
                    "raster tiles %": 100
                    * hy["tiles_raster"].sum()
                    / max(hy["tiles_raster"].sum() + hy["tiles_raycast"].sum(), 1),
                    "prediction error %, frames 8-": float(prediction_error(hy).median()),
                    "explored tiles": int(g[g["method"] == f"hybrid:{s}"]["explored"].sum()),
                    "adapt ms a frame": float(hy["adapt_ms"].median()),
                }
            )
    per_frame = frames.pivot_table(index=["flight", "tau", "frame"], columns="method", values="wall_ms").reset_index()
    return {
        "convergence: frames 8 to the end, ratios of median frame ms in this run": pd.DataFrame(rows),
        "frame ms per frame (median of repeats)": per_frame,
    }


def run(
    ctx,
    frames: int = 24,
    size: str = "640x360",
    repeats: int = 3,
    taus=(2 / 3, 2.0),
    flights=("flyover", "orbit", "dolly"),
    tile_size: int = 128,
    starts=STARTS,
) -> dict[str, pd.DataFrame]:
    """The benchmark on Puget: its tables keyed by title; size WIDTHxHEIGHT in pixels, tau in pixels."""
    from hybrid.camera.flight import preset
    from hybrid.camera.view import parse_size
    from hybrid.gl.context import gl_info
    from hybrid.terrain.datasets import puget

    w, h = parse_size(size, "size")
    hf = puget()
    models = {s: m for s, m in start_models(gl_info(ctx).renderer).items() if s in starts or s == "device"}
    parts = []
    for flight in flights:
        views = preset(flight, hf, frames, w, h).views()
        for tau in taus:
            part = draw_flight(ctx, hf, views, tau, models, repeats, tile_size)
            parts.append(part.assign(flight=flight, tau=round(tau, 4)))
    return summarize(pd.concat(parts, ignore_index=True))


def main(argv=None) -> int:
    """Run the adaptation benchmark on Puget and print its tables."""
    from hybrid.gl.context import gl_info, shared_context

    from .tables import text_tables

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--size", default="640x360")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--flights", default="flyover,orbit,dolly")
    a = ap.parse_args(argv)
    ctx = shared_context()
    print(f"device: {gl_info(ctx).renderer}")
    print(text_tables(run(ctx, a.frames, a.size, a.repeats, flights=a.flights.split(","))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
