"""`terrabench bench`: the ray-cast, raster, hybrid, planning and CPU benchmarks in one process, tables printed and saved."""

from __future__ import annotations

import argparse
import os
import platform
from pathlib import Path

import pandas as pd

from hybrid.atomic import write_text

from ..folders import writable_folder
from . import argtypes

HELP = (
    "the ray-cast, triangle-count, raster, hybrid, adaptation, choice, edit, planning and CPU benchmarks in one run, "
    "with the device named"
)
BENCHES = ("raycast", "triangles", "raster", "hybrid", "adapt", "choice", "edit", "planning", "cpu")
"""In the order they run: triangles (mesh triangle counts against error) and planning use the CPU alone; adapt is
the hybrid started from wrong cost models (``experiments.bench_adapt``), choice what choosing costs where the
hybrid's choices equal a pure method's (``experiments.bench_choice``), edit what one edit costs each strategy as
the terrain grows (``experiments.bench_edit``); cpu draws in a child process on Mesa's
no-op driver (``experiments.bench_cpu``)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The bench options: which benchmarks, frames per flight, and a markdown file to write."""
    p.add_argument(
        "--which",
        type=argtypes.names("--which", BENCHES),
        default=",".join(BENCHES),
        help="comma-separated: " + ", ".join(BENCHES),
    )
    p.add_argument("--frames", type=argtypes.int_in("--frames", 1, 1000), default=8, help="frames of each flight")
    p.add_argument("--out", default=None, help="also write the tables to this markdown file")


def benchmark(ctx, name: str, frames: int = 8) -> dict[str, pd.DataFrame]:
    """One benchmark's tables keyed by title; frames per flight (the triangle and raster benchmarks have none)."""
    if name == "raycast":
        from ..bench_raycast import run as raycast_run

        return raycast_run(ctx, frames=frames)
    if name == "triangles":
        from ..bench_raster import triangle_tables

        return triangle_tables()
    if name == "raster":
        from ..bench_raster import run as raster_run

        return raster_run(ctx)
    if name == "planning":
        from ..bench_planning import run as planning_run

        return planning_run(ctx, frames=frames)
    if name == "cpu":
        from ..bench_cpu import run as cpu_run

        return cpu_run(ctx, frames=frames)
    if name == "adapt":
        from ..bench_adapt import run as adapt_run

        return adapt_run(ctx, frames=max(frames, 24))  # its targets read frames 8 to 23 of a 24-frame flight
    if name == "edit":
        from ..bench_edit import run as edit_run

        return edit_run(ctx)
    if name == "choice":
        from ..bench_choice import run as choice_run

        return choice_run(ctx, frames=frames)
    from ..bench_hybrid import run as hybrid_run

    return hybrid_run(ctx, frames=frames)


def run(which=BENCHES, frames: int = 8, out=None, device: int | None = None) -> dict[str, dict[str, pd.DataFrame]]:
    """Run the benchmarks, print their tables and write them as markdown to out; returns the tables by benchmark."""
    from hybrid.gl.context import gl_info, shared_context

    from ..tables import markdown_tables, text_tables

    out = Path(out) if out else None
    if out is not None:
        writable_folder(out.parent if str(out.parent) else Path("."), "--out folder")
    ctx = shared_context(device)
    info = gl_info(ctx)
    head = (
        f"# terrabench benchmarks\n\ndevice: {info.renderer} ({info.version}); CPU cores: {os.cpu_count()}; "
        f"{platform.platform()}\n"
    )
    print(head)
    md, results = [head], {}
    for name in which:
        results[name] = benchmark(ctx, name, frames)
        print(f"## {name}\n\n{text_tables(results[name])}\n")
        md.append(f"## {name}\n\n{markdown_tables(results[name])}\n")
    if out is not None:
        write_text(out, "\n".join(md))
        print(f"wrote {out}")
    return results


def run_from_args(args: argparse.Namespace) -> int:
    """The bench command from parsed arguments; returns the exit code."""
    run(args.which, args.frames, args.out, args.device)
    return 0
