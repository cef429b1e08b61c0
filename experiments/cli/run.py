"""`terrabench run SPEC`: run (or resume) an experiment spec, paired flights or a stress spec."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..folders import writable_folder
from . import argtypes
from .options import add_reports_argument

HELP = "run an experiment spec (TOML): paired flights, tables, images"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The run options: the spec, where runs and reports go, and --quiet."""
    p.add_argument(
        "spec", help="experiment spec file (.toml) or a bundled one: default, tiny, stress, full-res, gpu, edit"
    )
    p.add_argument("--runs", default="runs", help="folder that holds run folders")
    p.add_argument("--name", default=None, help="run name (default: the spec's)")
    p.add_argument(
        "--frames",
        type=argtypes.int_in("--frames", 1, 100000),
        default=None,
        help="frames a flight, instead of the spec's (its image frames beyond them dropped)",
    )
    p.add_argument(
        "--sizes",
        type=argtypes.sizes("--sizes"),
        default=None,
        metavar="WxH[,WxH...]",
        help="image sizes in pixels, instead of the spec's",
    )
    p.add_argument("--report", action="store_true", help="write the report when done")
    add_reports_argument(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--freeze-model",
        action="store_true",
        help="the hybrid chooses by its starting cost model as it is (the spec's adapt = false)",
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run the configurations as tasks on the Dask cluster of this scheduler "
        "(needs terrabench[cluster]); each worker uses the EGL device TERRABENCH_GL_DEVICE names",
    )
    p.add_argument(
        "--scheduler-timeout",
        type=argtypes.positive_float("--scheduler-timeout", "seconds"),
        default=None,
        metavar="SECONDS",
        help="seconds to wait for --scheduler to answer (default 5)",
    )
    where.add_argument(
        "--workers",
        default=None,
        metavar="local:N",
        help="run the configurations on a local Dask cluster of N processes",
    )


def run(
    spec,
    runs="runs",
    name: str | None = None,
    report: bool = False,
    reports="reports",
    quiet: bool = False,
    device: int | None = None,
    scheduler: str | None = None,
    workers: str | None = None,
    frames: int | None = None,
    sizes: list[str] | None = None,
    freeze_model: bool = False,
    scheduler_timeout: float | None = None,
) -> Path:
    """Run a spec (a path, a bundled name or a parsed spec) into runs/<name>; returns the run folder. With a
    ``scheduler`` address or ``workers`` 'local:N' its configurations run on a Dask cluster; ``frames`` and
    ``sizes`` (pixels, 'WxH') replace a spec file's or bundled spec's own."""
    from hybrid.errors import TerrabenchError
    from hybrid.gl.context import shared_context

    from ..edit_run import run_edit_spec
    from ..edit_spec import EditSpec
    from ..report import write_run_report
    from ..runner import run_spec
    from ..spec import load_spec
    from ..stress import run_stress_spec
    from ..stress_spec import StressSpec

    overrides = {k: v for k, v in (("frames", frames), ("sizes", sizes)) if v is not None}
    if isinstance(spec, (str, Path)):
        spec = load_spec(spec, overrides)
    elif overrides:
        raise TerrabenchError("frames and sizes override a spec file or a bundled spec's name, not a parsed spec")
    if name:
        spec.name = name
    if freeze_model:
        if isinstance(spec, StressSpec):
            raise TerrabenchError("--freeze-model applies to paired-flight specs (a stress spec has no hybrid model)")
        spec.adapt = False
    writable_folder(Path(runs), "--runs")
    if report:
        writable_folder(Path(reports), "--reports")
    if scheduler or workers:
        if isinstance(spec, (StressSpec, EditSpec)):
            raise TerrabenchError("stress and edit specs run on one machine; drop --scheduler / --workers")
        folder = _run_on_cluster(spec, Path(runs), quiet, scheduler, workers, scheduler_timeout)
    else:
        runner = {StressSpec: run_stress_spec, EditSpec: run_edit_spec}.get(type(spec), run_spec)
        folder = runner(spec, Path(runs), shared_context(device), progress=not quiet)
    print(f"run folder: {folder}")
    if report:
        print(f"report: {write_run_report(folder, Path(reports), video=getattr(spec, 'video', False))}")
    return folder


def _run_on_cluster(
    spec, runs: Path, quiet: bool, scheduler: str | None, workers: str | None, scheduler_timeout: float | None
) -> Path:
    """Run a paired-flight spec's configurations on a Dask cluster (a ``scheduler`` address, or ``workers``
    'local:N'), closing the client and a local cluster afterwards; returns the run folder."""
    from ..cluster import CONNECT_TIMEOUT_S, connect
    from ..runner import run_spec

    client, cluster = connect(scheduler, workers, scheduler_timeout or CONNECT_TIMEOUT_S)
    try:
        return run_spec(spec, runs, progress=not quiet, client=client)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_from_args(args: argparse.Namespace) -> int:
    """The run command from parsed arguments; returns the exit code: 1 when any configuration failed."""
    from ..journal import failed_configs

    folder = run(
        args.spec,
        args.runs,
        args.name,
        args.report,
        args.reports,
        args.quiet,
        args.device,
        args.scheduler,
        args.workers,
        args.frames,
        args.sizes,
        args.freeze_model,
        args.scheduler_timeout,
    )
    failed = failed_configs(folder)
    if failed:
        print(
            f"terrabench: {len(failed)} configuration(s) failed (details in {folder / 'errors.jsonl'}):",
            file=sys.stderr,
        )
        for name, error in sorted(failed.items()):
            print(f"  {name}: {error.splitlines()[0] if error else ''}", file=sys.stderr)
        return 1
    return 0
