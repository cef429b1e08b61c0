"""Specs on a Dask cluster of 2 local processes: the serial run's rows, nothing lost when a worker dies
mid-task, and a worker without a GL context reported by name instead of a hang."""

import json
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

distributed = pytest.importorskip("distributed")

from experiments.cluster import worker_info  # noqa: E402
from experiments.runner import run_spec  # noqa: E402
from experiments.spec import parse_spec  # noqa: E402
from hybrid.errors import TerrabenchError  # noqa: E402

# the tiny spec at two taus: two groups of configurations, one task each, for the two workers; the hybrid frozen,
# as an adapting one's choices follow the times it measures, which no two runs share
TWO_GROUPS = (Path(__file__).parents[1] / "experiments" / "tiny.toml").read_text().replace(
    "taus = [0.6667]", "taus = [0.6667, 2.0]"
) + "adapt = false\n"


def two_groups():
    return parse_spec(TWO_GROUPS, "tiny at two taus")


# columns that depend on timing or on where a frame ran; every other column must match the serial run
TIMED = {
    "wall_ms",
    "wall_ms_min",
    "wall_ms_max",
    "wall_ms_repeats",
    "plan_ms",
    "draw_ms",
    "gpu_ms",
    "issue_ms",
    "cpu_ms",
    "upload_ms",
    "adapt_ms",
    "worker",
    "device",
}


def frames(folder):
    f = pd.read_parquet(folder / "frames.parquet").sort_values(["config", "frame"]).reset_index(drop=True)
    return f


def same_rows(a: pd.DataFrame, b: pd.DataFrame) -> None:
    assert list(zip(a["config"], a["frame"])) == list(zip(b["config"], b["frame"]))
    for col in sorted(set(a.columns) - TIMED):
        x, y = a[col].to_numpy(), b[col].to_numpy()
        if x.dtype.kind in "fc":
            assert np.allclose(x, y, equal_nan=True, rtol=1e-9, atol=0), col
        else:
            assert [repr(v) for v in x] == [repr(v) for v in y], col


@pytest.fixture(scope="module")
def serial(ctx, tmp_path_factory):
    return frames(run_spec(two_groups(), tmp_path_factory.mktemp("serial"), ctx, progress=False))


@pytest.fixture(scope="module")
def cluster():
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl,
        distributed.Client(cl) as client,
    ):
        yield cl, client


def test_cluster_run_has_the_serial_rows(serial, cluster, tmp_path):
    _, client = cluster
    folder = run_spec(two_groups(), tmp_path, progress=False, client=client)
    f = frames(folder)
    same_rows(f, serial)
    assert f["worker"].nunique() == 2 and (f.groupby("tau")["worker"].nunique() == 1).all()  # a group, one worker
    assert f["device"].str.contains("llvmpipe|NVIDIA|Mesa", regex=True).all()
    assert set(serial["worker"]) == {"local"}
    env = json.loads((folder / "env.json").read_text())
    assert len(env["workers"]) == 2 and all(w["error"] is None for w in env["workers"].values())
    assert not (folder / "errors.jsonl").exists()


def test_a_cluster_run_is_not_resumed_under_another_cost_model(cluster, tmp_path, monkeypatch):
    """env.json names the cost model each renderer's workers chose with; a resume whose client would send another
    (a recalibrated costs file) is refused before any task runs, and the journal is left as it was."""
    from hybrid.cost.model import load_cost_model, save_cost_model

    _, client = cluster
    spec = parse_spec(
        TWO_GROUPS.replace("frames = 3", "frames = 1").replace("image_frames = [1]", "image_frames = [0]"),
        "tiny, one frame",
    )
    monkeypatch.setenv("TERRABENCH_COSTS", str(tmp_path / "none.json"))
    folder = run_spec(spec, tmp_path / "runs", progress=False, client=client)
    env = json.loads((folder / "env.json").read_text())
    renderer = env["gl_renderer"][0]
    assert env["cost_model"][renderer]["source"].startswith("shipped")
    journal = (folder / "frames.jsonl").read_bytes()
    other = load_cost_model(renderer)
    ras = other.coefficients["raster"]
    other.renderer, other.coefficients = (
        renderer,
        {**other.coefficients, "raster": {**ras, "const": ras["const"] + 1.0}},
    )
    save_cost_model(other, tmp_path / "costs.json")
    monkeypatch.setenv("TERRABENCH_COSTS", str(tmp_path / "costs.json"))
    with pytest.raises(TerrabenchError, match="cost_model"):
        run_spec(spec, tmp_path / "runs", progress=False, client=client)
    assert (folder / "frames.jsonl").read_bytes() == journal


def test_a_worker_killed_mid_task_loses_nothing(serial, cluster, tmp_path):
    _, client = cluster
    killed = {}

    def kill_one_busy_worker():
        deadline = time.time() + 60
        while time.time() < deadline and not killed:
            busy = [a for a, tasks in client.processing().items() if tasks]
            if busy:
                time.sleep(0.3)  # inside the task: its frames are being drawn
                pid = client.run(worker_info, workers=[busy[0]])[busy[0]]["pid"]
                os.kill(pid, signal.SIGKILL)
                killed["pid"] = pid
            time.sleep(0.05)

    t = threading.Thread(target=kill_one_busy_worker)
    t.start()
    folder = run_spec(two_groups(), tmp_path, progress=False, client=client)
    t.join()
    assert killed, "no task was ever seen running"
    f = frames(folder)
    journal = [json.loads(line) for line in (folder / "frames.jsonl").read_text().splitlines()]
    keys = [(r["config"], r["frame"]) for r in journal]
    assert len(keys) == len(set(keys)) == 2 * 3 * 3  # every frame once: nothing lost, nothing twice
    same_rows(f, serial)
    assert not (folder / "errors.jsonl").exists()
    client.wait_for_workers(2, timeout=60)  # the nanny brought the worker back
    pids = {i["pid"] for i in client.run(worker_info).values()}
    assert killed["pid"] not in pids and len(pids) == 2


def test_a_worker_without_gl_is_reported_not_hung(tmp_path, capsys):
    from distributed import Nanny, Scheduler, SpecCluster

    workers = {
        "good": {"cls": Nanny, "options": {"nthreads": 1}},
        "bad": {"cls": Nanny, "options": {"nthreads": 1, "env": {"TERRABENCH_GL_DEVICE": "99"}}},
    }
    with (
        SpecCluster(workers=workers, scheduler={"cls": Scheduler, "options": {"dashboard": False}}) as cl,
        distributed.Client(cl) as client,
    ):
        client.wait_for_workers(2, timeout=60)
        folder = run_spec(two_groups(), tmp_path / "mixed", progress=False, client=client)
        out = capsys.readouterr().out
        assert "has no GL context and gets no task" in out and "99" in out
        f = frames(folder)
        assert len(f) == 18 and f["worker"].nunique() == 1
    with (
        distributed.LocalCluster(
            n_workers=1,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            env={"TERRABENCH_GL_DEVICE": "99"},
        ) as cl,
        distributed.Client(cl) as client,
    ):
        t0 = time.time()
        with pytest.raises(TerrabenchError, match=r"no worker of the cluster could make a GL context.*99"):
            run_spec(two_groups(), tmp_path / "none", progress=False, client=client)
        assert time.time() - t0 < 60


def test_calibrate_on_a_cluster_fits_one_model_per_device(cluster):
    from experiments.cli.options import TerrainOptions
    from experiments.cluster import calibrate_on_cluster
    from hybrid.strategies import candidates

    _, client = cluster
    args = (TerrainOptions("fbm", size_samples=129), ("flyover",), 2, (160, 90), 2 / 3, 32, 1, 0.3)
    models = calibrate_on_cluster(client, args)
    renderers = {i["renderer"] for i in client.run(worker_info).values()}
    assert [m.renderer for m in models] == sorted(renderers) and models[0].candidates == candidates()
    assert models[0].tiles >= 8 and all(np.isfinite(e) for e in models[0].fit_error.values())
