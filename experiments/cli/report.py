"""`terrabench report RUN`: the report of a run folder (paired flights or stress)."""

from __future__ import annotations

import argparse
from pathlib import Path

from .options import add_reports_argument

HELP = "write reports/<name>/report.md + .html from a run folder"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The report options: the run folder, where reports go, the name, and --video."""
    p.add_argument("run", help="run folder (runs/<name>)")
    add_reports_argument(p)
    p.add_argument("--name", default=None, help="report name (default: the run's)")
    p.add_argument("--video", action="store_true", help="also write the flight as GIF animations (spec video = true)")


def run(folder, reports="reports", name: str | None = None, video: bool = False) -> Path:
    """Write the report of a run folder into reports/<name>/; returns the markdown file."""
    from ..report import write_run_report

    path = write_run_report(Path(folder), Path(reports), name, video)
    html = path.with_suffix(".html")
    print(f"wrote {path}" + (f" and {html}" if html.exists() else ""))
    return path


def run_from_args(args: argparse.Namespace) -> int:
    """The report command from parsed arguments; returns the exit code."""
    run(args.run, args.reports, args.name, args.video)
    return 0
