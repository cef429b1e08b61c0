"""Choice benchmark: what choosing costs a frame where the hybrid's choices equal a pure method's.

    python -m experiments.bench_choice [--frames 8] [--size 640x360] [--repeats 5]

The hybrid (adapting, as by default) is given this device's cost model with every other candidate's per-frame
overhead set out of reach, so that every tile goes to one strategy, as a frame the hybrid would draw one way;
beside it the pure method draws the same frames, the two interleaved frame by frame, at tiles of 64, 128 and
256 on Puget's default flights. Its extra time is planning (features, triangle estimates, the choice) and
learning (``adapt_ms``); as by default it plans such a clear choice in full every fourth frame and reuses it in
between (``hybrid.cost.reuse``), and beside it the same hybrid planning every frame shows what choosing costs
each frame. Target: the hybrid's frame within 1.03x the pure method's. A second renderer of the pure method,
drawn like the first, gives the ratio a hybrid that cost nothing to choose would read (the floor of the noise).
"""

from __future__ import annotations

import argparse
import copy

import numpy as np
import pandas as pd

from hybrid.errors import TerrabenchError

TILE_SIZES = (64, 128, 256)
TARGET = "hybrid / pure (target <= 1.03)"
EVERY = "hybrid planning every frame"
AGAIN = "pure drawn again"
FLOOR = "pure again / pure (the floor)"


def forced(model, keep: str):
    """A copy of ``model`` under which every tile goes to ``keep``: the others' per-frame overheads out of reach."""
    m = copy.deepcopy(model)
    m.overhead = {s: (v if s == keep else 1e6) for s, v in m.overhead.items()}
    m.source = f"{model.source}, only {keep} within reach"
    return m


def draw(ctx, hf, views, tau: float, tile_size: int, model, method: str, repeats: int) -> pd.DataFrame:
    """Rows (policy, frame, wall_ms, wall_ms_repeats, plan_ms, adapt_ms, tiles): the pure method and the hybrid
    forced to its choices, interleaved, every frame ``repeats`` times."""
    from hybrid.renderer import Renderer

    rs = {}
    try:
        rs[method] = Renderer(ctx, hf, method, tile_size)
        rs[AGAIN] = Renderer(ctx, hf, method, tile_size)  # the pure method twice: the target's noise floor
        rs["hybrid"] = Renderer(ctx, hf, "hybrid", tile_size, cost_model=forced(model, method))
        rs[EVERY] = Renderer(ctx, hf, "hybrid", tile_size, cost_model=forced(model, method), reuse_choice=1)
        for r in rs.values():
            r.render(views[0], tau, read=False)
        got: dict = {(p, k): [] for p in rs for k in range(len(views))}
        for rep in range(repeats):
            for k, v in enumerate(views):
                for p in list(rs) if (k + rep) % 2 else list(rs)[::-1]:
                    got[(p, k)].append(rs[p].render(v, tau, read=False).stats)
    finally:
        for r in rs.values():
            r.release()
    rows = []
    for (p, k), st in got.items():
        if p in ("hybrid", EVERY) and any(
            (s.tiles_raycast if method == "raycast" else s.tiles_raster) != s.tiles for s in st
        ):
            raise TerrabenchError(f"the hybrid forced to {method} drew some tiles another way")
        w = [s.wall_ms for s in st]
        rows.append(
            {
                "policy": p,
                "frame": k,
                "wall_ms": float(np.median(w)),
                "wall_ms_repeats": w,
                "plan_ms": float(np.median([s.plan_ms for s in st])),
                "adapt_ms": float(np.median([s.adapt_ms for s in st])),
                "reused": float(np.mean([s.choice_reused for s in st])),
                "tiles": st[-1].tiles,
            }
        )
    return pd.DataFrame(rows)


def run(
    ctx,
    frames: int = 8,
    size: str = "640x360",
    repeats: int = 5,
    tau: float = 2 / 3,
    flights=("flyover", "orbit", "dolly"),
    methods=("raster", "raycast"),
    tile_sizes=TILE_SIZES,
) -> dict[str, pd.DataFrame]:
    """The benchmark's table on Puget: per tile size, flight and pure method, the hybrid's frame against it."""
    from hybrid.camera.flight import preset
    from hybrid.camera.view import parse_size
    from hybrid.cost.model import shipped_cost_model
    from hybrid.gl.context import gl_info
    from hybrid.terrain.datasets import puget

    from .noise import compare

    w, h = parse_size(size, "size")
    hf = puget()
    model = shipped_cost_model(gl_info(ctx).renderer)  # not the user's file: no earlier run's learning
    out = []
    for ts in tile_sizes:
        for flight in flights:
            views = preset(flight, hf, frames, w, h).views()
            for method in methods:
                df = draw(ctx, hf, views, tau, ts, model, method, repeats)
                by = {p: g for p, g in df.groupby("policy")}
                c = compare("hybrid", by["hybrid"], method, by[method])
                every = compare(EVERY, by[EVERY], method, by[method])
                again = compare(AGAIN, by[AGAIN], method, by[method])
                out.append(
                    {
                        "tile size": ts,
                        "flight": flight,
                        "pure": method,
                        "tiles": float(by[method]["tiles"].median()),
                        "pure ms": c.ms_b,
                        "hybrid ms": c.ms_a,
                        TARGET: c.ratio,
                        "reading": c.words(),
                        FLOOR: again.ratio,
                        "pure plan ms": float(by[method]["plan_ms"].median()),
                        "hybrid plan ms": float(by["hybrid"]["plan_ms"].median()),
                        "hybrid adapt ms": float(by["hybrid"]["adapt_ms"].median()),
                        "frames reused": float(by["hybrid"]["reused"].mean()),
                        "planning every frame / pure": every.ratio,
                        "planning every frame": every.words(),
                        "every-frame plan ms": float(by[EVERY]["plan_ms"].median()),
                        "every-frame adapt ms": float(by[EVERY]["adapt_ms"].median()),
                    }
                )
    return {
        f"choosing where the hybrid's choices equal a pure method's ({size}, tau {tau:.3g} px, {frames} frames, "
        f"median of {repeats} repeats)": pd.DataFrame(out)
    }


def main(argv=None) -> int:
    """Run the choice benchmark on Puget and print its table."""
    from hybrid.gl.context import gl_info, shared_context

    from .tables import text_tables

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--size", default="640x360")
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args(argv)
    ctx = shared_context()
    print(f"device: {gl_info(ctx).renderer}")
    print(text_tables(run(ctx, a.frames, a.size, a.repeats)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
