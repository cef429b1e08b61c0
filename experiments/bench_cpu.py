"""CPU benchmark: each policy's CPU time a frame with the GPU's work taken away, the policies interleaved in one run.

    python -m experiments.bench_cpu [--frames 8] [--size 640x360] [--repeats 5]

On llvmpipe the time a draw call takes to return includes the vertex, geometry and compute work, which run
inside it, so a frame's ``issue_ms`` there cannot tell the CPU's share. The frames are therefore drawn by a child
process on Mesa's no-op driver (``GALLIUM_NOOP=1``): every GL call is made and passes through Mesa's GL front end
(validation, state, uniform and buffer uploads), but nothing is drawn or computed, so the frame's wall time is its
CPU time: planning (tile selection and, for the mixed policies, features and choices) and issuing (Python,
moderngl, the GL front end). What a GPU's own driver spends on the same calls may differ; on a GPU (whose driver
ignores the variable) the child draws for real, and its ``issue_ms`` is the CPU's share, waits for the GPU left
out. The hybrid uses the cost model of the device the benchmark runs for, not the no-op driver's (which has none).
The images of the no-op driver are meaningless, and are not read.

Two ways of drawing, alternated in every repeat, so both see the same machine:
- back to back (the target's figure): each policy draws the flight's frames in a row without reading them back,
  as an application's frame loop does, the policies in turn;
- with read-back: every frame read back to the host (colour, distance), each frame drawn by every policy in
  turn, as the accuracy runs do. The read-back and the other policies' frames between two frames of a policy
  leave its data out of the CPU's caches, which makes the same work slower.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np
import pandas as pd

from hybrid.errors import TerrabenchError

POLICIES = ("raster", "raster_gs", "raycast", "hybrid", "hybrid=raster", "hybrid=raycast")
"""Policies drawn; ``hybrid=S`` is the hybrid with every candidate but S out of reach (``bench_choice.forced``): its
choices equal S's, so its extra CPU time over S is what choosing costs."""
FLIGHTS = ("flyover", "orbit", "dolly")
CHILD_TIMEOUT_S = 900
CHILD_ATTEMPTS = 3
TARGET = "CPU ms back to back (plan + issue + adapt; raster target <= 1)"
READ_BACK = "CPU ms with read-back"


def back_to_back_stats(renderers: dict, views, tau: float) -> dict:
    """{(policy, frame index): [FrameStats]}: each renderer draws every view in a row without reading it back."""
    return {(p, k): [r.render(v, tau, read=False).stats] for p, r in renderers.items() for k, v in enumerate(views)}


def measure(
    model_for: str, frames: int = 8, size: str = "640x360", repeats: int = 5, tile_size: int = 128, tau: float = 2 / 3
) -> dict:
    """In this process (the child): per flight, policy, frame and way of drawing (``back`` to back, or with
    ``read``-back), the median over repeats of plan, issue and wall ms on Puget's default flights, with the
    renderer's name; the hybrid with ``model_for``'s cost model."""
    import warnings

    from hybrid.camera.flight import preset
    from hybrid.camera.view import parse_size
    from hybrid.cost.model import load_cost_model
    from hybrid.gl.context import gl_info, shared_context
    from hybrid.terrain.datasets import puget

    warnings.simplefilter("ignore", RuntimeWarning)  # the no-op driver's read-backs hold no image
    ctx = shared_context()
    w, h = parse_size(size, "size")
    hf = puget()
    model = load_cost_model(model_for)
    rows, mixed = [], []
    for fname in FLIGHTS:
        views = preset(fname, hf, frames, w, h).views()
        renderers: dict = {}
        try:
            _warm_renderers(renderers, ctx, hf, model, views, tile_size, tau)
            rows += _median_rows(fname, renderers, views, tau, repeats)
            mixed += [{"flight": fname, **m} for m in mixed_parts(renderers["hybrid"], views, tau, repeats)]
        finally:
            for r in renderers.values():
                r.release()
    return {"renderer": gl_info(ctx).renderer, "rows": rows, "mixed": mixed}


def _warm_renderers(renderers: dict, ctx, hf, model, views, tile_size: int, tau: float) -> None:
    """Make each policy's renderer into ``renderers`` (the hybrid's with ``model``) and draw the views once with it:
    uploads, estimates and shader compiles out of the way."""
    from hybrid.renderer import make_renderer

    from .bench_choice import forced

    for p in POLICIES:
        base, _, only = p.partition("=")
        opts = {"cost_model": forced(model, only) if only else model} if base == "hybrid" else {}
        renderers[p] = make_renderer(ctx, hf, base, tile_size=tile_size, **opts)
        for v in views:  # warm: uploads, estimates, shader compiles
            renderers[p].render(v, tau)


def _median_rows(fname: str, renderers: dict, views, tau: float, repeats: int) -> list[dict]:
    """Per policy, frame and way of drawing (``back`` to back, ``read``-back), the median plan, issue, wall and
    adapt ms over ``repeats``, the two ways alternating."""
    from .bench_hybrid import interleaved_stats

    got: dict[tuple, list] = {("back", p, k): [] for p in POLICIES for k in range(len(views))}
    got.update({("read", p, k): [] for p in POLICIES for k in range(len(views))})
    for _ in range(repeats):  # the two ways alternate: one machine for both
        for way, stats in (
            ("back", back_to_back_stats(renderers, views, tau)),
            ("read", interleaved_stats(renderers, views, tau, 1)),
        ):
            for (p, k), x in stats.items():
                got[(way, p, k)] += x
    rows = []
    for (way, p, k), x in got.items():
        plan, issue, wall, adapt = np.median([(s.plan_ms, s.issue_ms, s.wall_ms, s.adapt_ms) for s in x], axis=0)
        rows.append(
            {
                "flight": fname,
                "policy": p,
                "frame": k,
                "way": way,
                "plan_ms": plan,
                "issue_ms": issue,
                "wall_ms": wall,
                "adapt_ms": adapt,
            }
        )
    return rows


def mixed_parts(r, views, tau: float, repeats: int) -> list[dict]:
    """Per view whose hybrid plan mixes strategies: the issue ms of the whole frame and of each strategy's tiles
    drawn alone (the same plans), medians over ``repeats``."""
    out = []
    for k, v in enumerate(views):
        plans = r.plan(v, tau)
        used = sorted({p.choice for p in plans})
        if len(used) < 2:
            continue
        whole, parts = [], []
        for _ in range(repeats):
            whole.append(r.render(v, tau, plans=plans, read=False).stats.issue_ms)
            parts.append(
                sum(
                    r.render(v, tau, plans=[p for p in plans if p.choice == s], read=False).stats.issue_ms for s in used
                )
            )
        out.append(
            {
                "frame": k,
                "strategies": "+".join(used),
                "whole_ms": float(np.median(whole)),
                "parts_ms": float(np.median(parts)),
            }
        )
    return out


def run_child(model_for: str, frames: int, size: str, repeats: int) -> dict:
    """``measure`` in a child process on Mesa's no-op driver (the same EGL device as this process's), with the
    number of ``attempts`` it took: a child killed by a signal is run again, at most ``CHILD_ATTEMPTS`` times in
    all (the no-op driver has crashed inside a buffer write in about one run in fifteen here; a crash leaves no
    numbers, so those of a run that finished are whole)."""
    env = {**os.environ, "GALLIUM_NOOP": "1"}
    cmd = [
        sys.executable,
        "-m",
        "experiments.bench_cpu",
        "--child",
        "--model-for",
        model_for,
        "--frames",
        str(frames),
        "--size",
        size,
        "--repeats",
        str(repeats),
    ]
    for attempt in range(1, CHILD_ATTEMPTS + 1):
        try:
            done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=CHILD_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise TerrabenchError(f"the CPU benchmark's child process ran over {CHILD_TIMEOUT_S} s") from None
        if done.returncode >= 0 or attempt == CHILD_ATTEMPTS:
            break
    lines = done.stdout.strip().splitlines()
    if done.returncode != 0 or not lines:
        raise TerrabenchError(
            f"the CPU benchmark's child process failed (exit {done.returncode}, attempt {attempt} "
            f"of {CHILD_ATTEMPTS}): {done.stderr.strip()[-2000:]}"
        )
    return {**json.loads(lines[-1]), "attempts": attempt}


def summarize(result: dict) -> dict[str, pd.DataFrame]:
    """Per flight and policy, the medians over frames: plan, issue and CPU (plan + issue) ms drawn back to back,
    and CPU ms with the read-back, with their ratio."""
    df = pd.DataFrame(result["rows"])
    if "adapt_ms" not in df:
        df["adapt_ms"] = 0.0
    df["cpu_ms"] = df["plan_ms"] + df["issue_ms"] + df["adapt_ms"]
    t = df.groupby(["way", "flight", "policy"], sort=False)[["plan_ms", "issue_ms", "adapt_ms", "cpu_ms"]].median()
    back, read = t.loc["back"], t.loc["read"]
    out = back.rename(columns={"plan_ms": "plan ms", "issue_ms": "issue ms", "adapt_ms": "adapt ms", "cpu_ms": TARGET})
    out[READ_BACK] = read["cpu_ms"]
    out["with / without read-back"] = read["cpu_ms"] / back["cpu_ms"]
    renderer = result["renderer"]
    how = (
        "Mesa's no-op driver: every GL call made, no GPU work"
        if renderer == "NOOP"
        else f"{renderer}, drawing for real (issue without the waits for the GPU)"
    )
    if result.get("attempts", 1) > 1:
        how += f"; the child crashed and was run again, {result['attempts']} runs in all"
    tables = {f"CPU time a frame on Puget, median of frames ({how})": out.reset_index()}
    if result.get("mixed"):
        m = pd.DataFrame(result["mixed"])
        m["extra_ms"] = m["whole_ms"] - m["parts_ms"]
        tables["a mixed frame's issue against its strategies' tiles drawn alone (target: extra <= 0.5 ms)"] = (
            m.groupby("flight", sort=False)
            .agg(
                frames=("frame", "count"),
                whole_ms=("whole_ms", "median"),
                parts_ms=("parts_ms", "median"),
                extra_ms=("extra_ms", "median"),
                extra_max_ms=("extra_ms", "max"),
            )
            .reset_index()
        )
    return tables


def run(ctx=None, frames: int = 8, size: str = "640x360", repeats: int = 5) -> dict[str, pd.DataFrame]:
    """The benchmark's table keyed by title; the frames drawn in a child process (``run_child``), the hybrid with the
    cost model of ``ctx``'s device (the default process context when None)."""
    from hybrid.gl.context import gl_info, shared_context

    renderer = gl_info(ctx if ctx is not None else shared_context()).renderer
    return summarize(run_child(renderer, frames, size, repeats))


def main(argv=None) -> int:
    """Run the CPU benchmark and print its table (``--child``: measure here and print the rows as JSON)."""
    from .tables import text_tables

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--size", default="640x360")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--model-for", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        print(json.dumps(measure(a.model_for, a.frames, a.size, a.repeats)))
        return 0
    print(text_tables(run(None, a.frames, a.size, a.repeats)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
