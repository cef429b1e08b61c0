"""A spec's configurations as tasks on a Dask cluster: one GL context per worker, the journal kept here.

``terrabench run SPEC --scheduler ADDRESS`` uses a running Dask scheduler (SSH, Slurm through
dask-jobqueue, Kubernetes); ``--workers local:N`` starts a local cluster of N single-threaded processes.
Each worker makes its headless GL context once, in the thread that runs its tasks (``GLWorkerPlugin``),
on the EGL device its environment names (TERRABENCH_GL_DEVICE, else the default), and reports its GL
renderer; a worker whose context cannot be made is reported by name and gets no task (tasks ask for the
worker resource the plugin sets only where the context works, so a worker restarted by its nanny takes tasks
again once its context is made). A group of configurations timed together (``config_task.run_group``) is
one task; the task gets the spec and the configurations (pickled dataclasses; datasets travel as paths or names
and are loaded on the worker) and returns their rows and images, which this process journals as they arrive: a resumed run redoes
nothing finished, and the task of a worker that dies is run again elsewhere by Dask, never journaled twice.
Rows carry the device (GL renderer) and the worker that timed them; each task uses the cost model
calibrated for its worker's device when this process's costs file has one.
"""

from __future__ import annotations

import asyncio
import os
from pathlib import Path
from typing import TYPE_CHECKING

from hybrid.errors import TerrabenchError

from .run_config import Config
from .spec import Spec

PLUGIN = "terrabench-gl"
GL_RESOURCE = "terrabench_gl"  # a worker resource the plugin sets once the worker's GL context works
READY_TIMEOUT_S = 120.0
CONNECT_TIMEOUT_S = 5.0
"""Seconds to wait for a --scheduler to answer before giving up (--scheduler-timeout changes it)."""


def _distributed():
    try:
        import distributed
    except ImportError:
        raise TerrabenchError("running on a cluster needs Dask: pip install 'terrabench[cluster]'") from None
    return distributed


if TYPE_CHECKING:
    from distributed.diagnostics.plugin import WorkerPlugin
else:
    try:
        from distributed.diagnostics.plugin import WorkerPlugin
    except ImportError:  # without the cluster extra the plugin is never registered
        WorkerPlugin = object


class GLWorkerPlugin(WorkerPlugin):
    """Makes the worker's GL context in its task thread and keeps the per-process task state."""

    name = PLUGIN

    async def setup(self, worker):
        """Make the context in the executor thread that runs the tasks; record the renderer or the error."""

        def make():
            from hybrid.gl.context import gl_info, shared_context

            from .config_task import TaskState

            try:
                ctx = shared_context()
                return {"state": TaskState(ctx), "renderer": gl_info(ctx).renderer, "error": None}
            except Exception as exc:  # reported to the client, never raised into the worker
                return {"state": None, "renderer": None, "error": f"{type(exc).__name__}: {exc}"}

        loop = asyncio.get_running_loop()
        worker.terrabench = await loop.run_in_executor(worker.executors["default"], make)
        if worker.terrabench["error"] is None:  # tasks ask for this resource: only GL workers run them
            await worker.set_resources(**{GL_RESOURCE: 1})


def worker_info(dask_worker) -> dict:
    """On a worker (``client.run`` passes it): its GL renderer or the reason it has none, and its process id."""
    tb = getattr(dask_worker, "terrabench", None) or {"renderer": None, "error": "the terrabench plugin did not run"}
    return {"renderer": tb["renderer"], "error": tb["error"], "pid": os.getpid()}


def group_task(spec: Spec, items: list[tuple[Config, list[int]]], costs: dict):
    """On a worker: run one group of configurations with the worker's GL context (config_task.run_group)."""
    from distributed import get_worker

    from hybrid.cost.model import costs_file_model

    from .config_task import run_group

    w = get_worker()
    tb = getattr(w, "terrabench", None)
    if tb is None or tb["state"] is None:
        raise TerrabenchError(f"worker {w.address} has no GL context: {tb['error'] if tb else 'plugin missing'}")
    state = tb["state"]
    state.cost_model = costs_file_model(costs, tb["renderer"], "costs file sent by the client")
    return run_group(spec, items, state, extra={"device": tb["renderer"], "worker": w.address})


def connect(scheduler: str | None = None, workers: str | None = None, timeout: float = CONNECT_TIMEOUT_S):
    """(client, cluster or None): a client of the scheduler at ADDRESS (waiting at most ``timeout`` seconds for
    it), or of a new local cluster 'local:N'."""
    distributed = _distributed()
    if scheduler and workers:
        raise TerrabenchError("give --scheduler or --workers, not both")
    if workers:
        if not workers.startswith("local:") or not workers[6:].isdigit() or not 1 <= int(workers[6:]) <= 64:
            raise TerrabenchError(f"--workers must be local:N with N in [1, 64], got {workers!r}")
        cluster = distributed.LocalCluster(
            n_workers=int(workers[6:]), threads_per_worker=1, processes=True, dashboard_address=None
        )
        return distributed.Client(cluster), cluster
    try:
        return distributed.Client(scheduler, timeout=f"{timeout:g}s"), None
    except ValueError as exc:
        raise TerrabenchError(
            f"--scheduler {scheduler!r} is not a Dask scheduler address such as tcp://HOST:8786 ({exc})"
        ) from None
    except (OSError, TimeoutError) as exc:
        raise TerrabenchError(
            f"cannot reach the Dask scheduler at {scheduler!r} within {timeout:g} s ({exc}); "
            "check the address, or wait longer with --scheduler-timeout SECONDS"
        ) from None


def ready_workers(client) -> dict[str, dict]:
    """Register the GL plugin and return every worker's info; workers without a GL context are reported."""
    if not client.scheduler_info()["workers"]:
        client.wait_for_workers(1, timeout=READY_TIMEOUT_S)
    client.register_plugin(GLWorkerPlugin())
    return client.run(worker_info)


def run_on_cluster(spec: Spec, folder: Path, client, progress: bool = True) -> None:
    """Run every pending configuration of spec as a task on the client's cluster, journaling into folder."""
    from distributed import as_completed

    from hybrid.cost.model import read_costs_file

    from .config_task import ConfigResult, groups
    from .journal import Journal, pending, record
    from .progress import Progress

    info = ready_workers(client)
    good = [a for a, i in info.items() if i["error"] is None]
    for a, i in info.items():
        if i["error"] is not None:
            print(f"terrabench: worker {a} has no GL context and gets no task: {i['error']}")
    if not good:
        raise TerrabenchError(
            "no worker of the cluster could make a GL context: "
            + "; ".join(f"{a}: {i['error']}" for a, i in info.items())
        )
    costs = read_costs_file()
    journal = Journal(folder)
    todo = pending(spec, journal)
    total = len(spec.configs()) * spec.frames
    bar = Progress(total, total - sum(len(t) for _, t in todo), progress)
    futures = {
        client.submit(
            group_task,
            spec,
            items,
            costs,
            key=f"terrabench-{spec.name}-{items[0][0].config}",
            pure=False,
            resources={GL_RESOURCE: 1},
        ): items
        for items in groups(todo)
    }
    for fut in as_completed(futures):
        items = futures[fut]
        try:
            results = fut.result()
        except Exception as exc:  # the task itself failed (e.g. on every worker it was tried on)
            results = [ConfigResult(c, error={**c.row(), "error": f"{type(exc).__name__}: {exc}"}) for c, _ in items]
        for result, (c, frames) in zip(results, items):
            record(folder, journal, result)
            bar.done += len(frames) - 1
            bar.step(c.config)
        journal.write_tables()
    bar.close()


def cluster_environment(client) -> dict:
    """The run's env.json on a cluster: this process's packages, every worker's GL renderer (or error) and the cost
    model each renderer's workers choose with (the client's costs file's, else the defaults as shipped here)."""
    from hybrid.cost.model import read_costs_file

    from .environment import cost_model_fingerprint, package_versions

    info = ready_workers(client)
    renderers = sorted({i["renderer"] for i in info.values() if i["renderer"]})
    sent = read_costs_file()
    return {
        "scheduler": client.scheduler.address,
        "workers": info,
        "packages": package_versions(),
        "gl_renderer": renderers,
        "cost_model": {r: cost_model_fingerprint(r, sent) for r in renderers},
    }


def calibrate_task(args: tuple) -> dict:
    """On a worker: calibrate its device (experiments.cli.calibrate.calibrate_here) and return the model's dict."""
    from distributed import get_worker

    from .calibration import calibrate_here

    tb = getattr(get_worker(), "terrabench", None)
    if tb is None or tb["state"] is None:
        raise TerrabenchError(f"worker {get_worker().address} has no GL context")
    return calibrate_here(tb["state"].ctx, *args).model.to_dict()


def calibrate_on_cluster(client, args: tuple) -> list:
    """One calibration per distinct GL renderer of the cluster's workers, each on one of its workers."""
    from hybrid.cost.model import cost_model_from_dict

    info = ready_workers(client)
    by_device: dict[str, str] = {}  # GL renderer -> the first worker's address
    for address, i in sorted(info.items()):
        if i["error"] is None:
            by_device.setdefault(i["renderer"], address)
    if not by_device:
        raise TerrabenchError("no worker of the cluster could make a GL context")
    futures = [client.submit(calibrate_task, args, workers=[a], pure=False) for a in by_device.values()]
    return [cost_model_from_dict(f.result(), f"calibrated on {a}") for f, a in zip(futures, by_device.values())]
