"""`terrabench run SPEC`: every configuration of a spec over the same (paired) views, written as it goes.

Run folder layout (runs/<name>/):
    spec.json, env.json             what was asked and where it ran
    .lock                           held while a run writes here (experiments.runlock): one run at a time
    frames.jsonl                    the journal: one finished frame a line (its row with its tile rows, so
                                    the two are never parted), flushed as it is written
    errors.jsonl                    configurations that failed, with their error; the rest goes on
    frames.parquet, tiles.parquet   the tables, rewritten from the journal after every group
    images/                         colour + depth of the spec's image_frames for every configuration
An interrupted run resumes from the journal without redoing finished (configuration, frame) rows; a
configuration resumed part-way first replays its earlier frames untimed, so that its GPU tile cache (and
with it the memory and upload columns) is in the state an uninterrupted run would have. Every table and
image is written under a temporary name and renamed (hybrid.atomic).

How a group of configurations (the same paired views and tau) is drawn, timed interleaved and measured is
``experiments.config_task``; with ``--workers`` or ``--scheduler`` the groups run as tasks on a Dask cluster
(``experiments.cluster``) and this process keeps the journal, so a resumed or distributed run never loses or
repeats a frame.
"""

from __future__ import annotations

from pathlib import Path

from hybrid.atomic import remove_stale_temps, write_json
from hybrid.errors import TerrabenchError

from .environment import environment
from .folders import read_json
from .journal import Journal, pending, record
from .progress import Progress
from .runlock import RunLock
from .spec import Spec


def run_spec(spec: Spec, runs_dir, ctx=None, progress: bool = True, fail_fast: bool = False, client=None) -> Path:
    """Run (or resume) every configuration of spec into runs_dir/<name>; returns the run folder.

    With a Dask ``client`` the configurations run as tasks on its cluster (``experiments.cluster``)."""
    from hybrid.gl.context import shared_context

    from .spec_datasets import check_dataset_paths

    check_dataset_paths(spec.datasets, f"spec {spec.name!r}")
    runs_dir = Path(runs_dir)
    folder = runs_dir / spec.name
    try:
        (folder / "images").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TerrabenchError(f"cannot create run folder {folder}: {exc.strerror or exc}") from None
    with RunLock(folder):
        for where in (folder, folder / "images"):  # what a killed run was writing
            remove_stale_temps(where)
        old = folder / "spec.json"
        if old.exists() and not spec.same_as(read_json(old, "run spec")):
            raise TerrabenchError(f"{folder} holds a run of a different spec; choose another name or folder")
        write_json(old, spec.to_dict())
        if client is not None:
            from .cluster import cluster_environment, run_on_cluster

            env = cluster_environment(client)
            _check_resume(folder, env)
            write_json(folder / "env.json", env)
            run_on_cluster(spec, folder, client, progress)
        else:
            ctx = ctx or shared_context()
            env = environment(ctx)
            _check_resume(folder, env)
            write_json(folder / "env.json", env)
            _run_configs(spec, folder, ctx, progress, fail_fast)
    return folder


def _check_resume(folder: Path, env: dict) -> None:
    """Refuse to add frames to a run folder whose earlier frames ran on another GL renderer or cost model."""
    from .environment import resume_mismatch

    frames, old = folder / "frames.jsonl", folder / "env.json"
    if not (frames.exists() and frames.stat().st_size and old.exists()):
        return
    why = resume_mismatch(read_json(old, "run environment"), env)
    if why:
        raise TerrabenchError(
            f"{folder} holds frames run with another setup ({why}); resuming would mix them in "
            f"one table: choose another --name or --runs folder, or remove {folder}"
        )


def _run_configs(spec: Spec, folder: Path, ctx, progress: bool, fail_fast: bool) -> None:
    """The body of run_spec, under the folder's lock: every configuration not yet in the journal, a group of
    configurations timed together at a time (experiments.config_task.run_group)."""
    from hybrid.gl.context import gl_info

    from .config_task import TaskState, groups, run_group

    journal = Journal(folder)
    todo = pending(spec, journal)
    total = len(spec.configs()) * spec.frames
    bar = Progress(total, total - sum(len(t) for _, t in todo), progress)
    state = TaskState(ctx)
    extra = {"device": gl_info(ctx).renderer, "worker": "local"}
    try:
        for group in groups(todo):
            for result in run_group(spec, group, state, bar.step, fail_fast, extra):
                bar.done += result.unreached
                record(folder, journal, result)
            journal.write_tables()
    finally:
        state.release_group()
    bar.close()
    journal.write_tables()
    if state.learned is not None:
        from hybrid.cost.model import save_cost_model

        print(f"learned cost model ({state.learned.adapted_frames} frames) saved to {save_cost_model(state.learned)}")
