"""`terrabench stress`: scenes and views made to break methods; failure table, chart and report section."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..folders import writable_folder
from ..stress import METHODS, SCENES, VIEWS
from . import argtypes

HELP = "scenes and views that break methods: failure table, chart, report section"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The stress options: scenes, views, methods, terrain and viewport sizes, tile size and output folder."""
    for option, allowed in (("--scenes", SCENES), ("--views", VIEWS), ("--methods", METHODS)):
        p.add_argument(
            option,
            type=argtypes.names(option, allowed),
            default=",".join(allowed),
            help="comma-separated: " + ", ".join(allowed),
        )
    p.add_argument(
        "--size-samples",
        type=argtypes.int_in("--size-samples", 17, 4097),
        default=257,
        help="samples a side of each scene",
    )
    p.add_argument("--size", type=argtypes.size("--size"), default="320x180", help="viewport WIDTHxHEIGHT")
    p.add_argument("--tile-size", type=argtypes.power_of_two("--tile-size"), default=64, help="cells per tile side")
    p.add_argument("--out", default="reports/stress", help="folder for stress.md, the chart and the table")
    p.add_argument("--quiet", action="store_true")


def run(
    scenes=SCENES,
    views=VIEWS,
    methods=METHODS,
    size_samples: int = 257,
    size: tuple[int, int] = (320, 180),
    tile_size: int = 64,
    out="reports/stress",
    quiet: bool = False,
    device: int | None = None,
) -> Path:
    """Measure every (scene, view, method) and write stress.md, the chart and the table to out; returns stress.md."""
    from hybrid.gl.context import shared_context

    from ..stress import stress_table
    from ..stress_report import write_stress_report

    folder = writable_folder(Path(out), "--out")
    df = stress_table(shared_context(device), scenes, views, methods, size_samples, size, tile_size, not quiet)
    path = write_stress_report(df, folder)
    print(f"wrote {path}")
    return path


def run_from_args(args: argparse.Namespace) -> int:
    """The stress command from parsed arguments; returns the exit code."""
    run(
        args.scenes,
        args.views,
        args.methods,
        args.size_samples,
        args.size,
        args.tile_size,
        args.out,
        args.quiet,
        args.device,
    )
    return 0
