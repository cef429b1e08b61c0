"""Runs lose nothing and succeed on nothing silently: the folder lock, resuming at every journal write point,
exit codes of failed configurations, and outputs that land whole or not at all (disk full included)."""

import errno
import json
import shutil
import subprocess
import sys
import time

import pandas as pd
import pytest

from experiments.cli import main
from experiments.runlock import RunLock
from experiments.runner import run_spec
from experiments.spec import parse_spec
from hybrid.atomic import atomic_path
from hybrid.errors import TerrabenchError
from hybrid.strategies import candidates

SMALL = """
name = "s"
datasets = ["fbm"]
dataset_size = 129
flights = ["flyover"]
frames = 3
policies = ["raycast", "hybrid"]
sizes = ["96x64"]
repeats = 3
tile_size = 32
supersample = 1
image_frames = [0]
"""

HOLDER = """
import sys, time
from experiments.runlock import RunLock
lock = RunLock(sys.argv[1]).acquire()
print("held", flush=True)
time.sleep(60)
"""


def test_a_second_run_is_refused_by_pid_and_a_dead_holders_lock_is_taken(tmp_path):
    p = subprocess.Popen([sys.executable, "-c", HOLDER, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "held"
        with pytest.raises(TerrabenchError, match=f"in use by another run \\(pid {p.pid} "):
            RunLock(tmp_path).acquire()
    finally:
        p.kill()
        p.wait()
    with RunLock(tmp_path) as lock:  # the killed holder's lock is free again
        assert f"pid {__import__('os').getpid()}" in lock.path.read_text()


def test_run_spec_refuses_a_folder_in_use(ctx, tmp_path):
    (tmp_path / "s").mkdir()
    with RunLock(tmp_path / "s"), pytest.raises(TerrabenchError, match="in use by another run"):
        run_spec(parse_spec(SMALL), tmp_path, ctx, progress=False)
    assert not (tmp_path / "s" / "frames.jsonl").exists()


def _comparable(folder, name):
    """A table without its timing columns, in a fixed row order."""
    t = pd.read_parquet(folder / f"{name}.parquet")
    t = t[[c for c in t.columns if not (c.endswith("_ms") or c.startswith("wall_ms"))]]
    keys = [c for c in ("config", "frame", "level", "tx", "ty") if c in t]
    return t.sort_values(keys).reset_index(drop=True)


def test_resume_after_a_kill_at_every_journal_write_equals_an_uninterrupted_run(ctx, tmp_path):
    # frozen: an adapting hybrid's choices follow the times it measures, which no two runs share
    frozen = SMALL + "adapt = false\n"
    whole = run_spec(parse_spec(frozen), tmp_path / "whole", ctx, progress=False)
    lines = (whole / "frames.jsonl").read_text().splitlines()
    assert len(lines) == 6 and all("tiles_rows" in json.loads(line) for line in lines)  # a frame with its tiles
    frames, tiles = _comparable(whole, "frames"), _comparable(whole, "tiles")
    # the hybrid's rows: a candidate strategy and the features it chose from, for every tile of every frame
    assert len(tiles) >= 6 and tiles["strategy"].isin(candidates()).all() and (tiles["f_pixels"] > 0).any()
    for kept in range(len(lines)):
        folder = tmp_path / f"cut{kept}" / "s"
        folder.mkdir(parents=True)
        shutil.copy(whole / "spec.json", folder / "spec.json")
        torn = lines[kept][:25]  # killed while writing the next record
        (folder / "frames.jsonl").write_text("".join(line + "\n" for line in lines[:kept]) + torn)
        run_spec(parse_spec(frozen), folder.parent, ctx, progress=False)
        pd.testing.assert_frame_equal(_comparable(folder, "frames"), frames, check_exact=False, rtol=1e-6)
        pd.testing.assert_frame_equal(_comparable(folder, "tiles"), tiles, check_exact=False, rtol=1e-6)


def test_resuming_with_another_cost_model_is_refused(ctx, tmp_path, monkeypatch):
    """A run folder's frames were chosen by one cost model; a resume under another (recalibrated here through the
    user's costs file) would put both in one table: it is refused, naming the two models, and the journal is left
    as it was. Under the first model again it resumes."""
    from hybrid.cost.model import load_cost_model, save_cost_model
    from hybrid.gl.context import gl_info

    spec = parse_spec(SMALL.replace("frames = 3", "frames = 1"))
    monkeypatch.setenv("TERRABENCH_COSTS", str(tmp_path / "none.json"))  # the shipped model
    folder = run_spec(spec, tmp_path / "runs", ctx, progress=False)
    journal = (folder / "frames.jsonl").read_bytes()
    renderer = gl_info(ctx).renderer
    other = load_cost_model(renderer)
    ray = other.coefficients["raycast"]
    other.renderer, other.coefficients = (
        renderer,
        {**other.coefficients, "raycast": {**ray, "const": ray["const"] + 1.0}},
    )
    save_cost_model(other, tmp_path / "costs.json")
    monkeypatch.setenv("TERRABENCH_COSTS", str(tmp_path / "costs.json"))
    with pytest.raises(TerrabenchError, match=r"cost_model .*shipped.* then, .*costs\.json"):
        run_spec(spec, tmp_path / "runs", ctx, progress=False)
    assert (folder / "frames.jsonl").read_bytes() == journal
    monkeypatch.setenv("TERRABENCH_COSTS", str(tmp_path / "none.json"))
    run_spec(spec, tmp_path / "runs", ctx, progress=False)
    assert (folder / "frames.jsonl").read_bytes() == journal  # nothing left to run, nothing added


def test_run_exits_nonzero_naming_the_failed_configuration(tmp_path, capsys):
    spec = tmp_path / "bad.toml"
    (tmp_path / "broken.tif").write_bytes(b"not a raster")  # there, so the run starts; unreadable
    spec.write_text(
        SMALL.replace('datasets = ["fbm"]', f'datasets = ["fbm", "{tmp_path / "broken.tif"}"]').replace(
            "frames = 3", "frames = 1"
        )
    )
    rc = main(["run", str(spec), "--runs", str(tmp_path / "runs"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 1
    assert (
        "2 configuration(s) failed" in err
        and "broken-s0-flyover-96x64-tau0.6667-triangles-raycast: " in err
        and "broken.tif: not a readable raster" in err
    )
    assert len(pd.read_parquet(tmp_path / "runs" / "s" / "frames.parquet")) == 2  # the good ones went on


WRITERS = {
    "png": "save_png(p, np.random.default_rng(0).integers(0, 255, (64, 64, 3), dtype=np.uint8))",
    "npy": "save_npy(p, np.arange(5000.0))",
    "parquet": "write_parquet(p, pd.DataFrame({'a': np.arange(5000)}))",
    "text": "write_text(p, 'x' * 9000)",
}
FILE_LIMIT = """
import resource, signal, sys
import numpy as np, pandas as pd
from hybrid.atomic import save_npy, save_png, write_parquet, write_text
from hybrid.errors import TerrabenchError
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (600, 600))     # every write past 600 bytes fails, as on a full disk
p = sys.argv[1]
try:
    {call}
except TerrabenchError as exc:
    print("refused:", exc)
"""


@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_outputs_land_whole_or_not_at_all(tmp_path, kind):
    path = tmp_path / f"out.{kind}"
    path.write_bytes(b"earlier")
    code = FILE_LIMIT.replace("{call}", WRITERS[kind])
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("refused: cannot write") and str(path) in out.stdout
    assert path.read_bytes() == b"earlier"  # the earlier version is untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]  # and no partial file beside it
    done = subprocess.run(
        [sys.executable, "-c", code.replace("(600, 600)", "(10**9, 10**9)"), str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0 and not done.stdout and path.stat().st_size > 600


def test_a_full_disk_is_one_message_and_leaves_nothing(tmp_path):
    path = tmp_path / "img.png"
    with (
        pytest.raises(TerrabenchError, match=f"disk full while writing {path}; nothing was written"),
        atomic_path(path) as tmp,
    ):
        tmp.write_bytes(b"partial")
        raise OSError(errno.ENOSPC, "No space left on device")
    assert not list(tmp_path.iterdir())


def test_lock_wait_is_not_a_hang(tmp_path):
    t = time.perf_counter()
    with RunLock(tmp_path), pytest.raises(TerrabenchError):
        RunLock(tmp_path).acquire()
    assert time.perf_counter() - t < 2.0


RENDER_FULL = """
import resource, signal, sys
from experiments.cli import main
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (20000, 20000))   # the PNG fits, the depth does not
sys.exit(main(["render", "--dataset", "fbm", "--size-samples", "129", "--size", "160x90", "--method", "raycast", "--tile-size", "32", "--out", sys.argv[1]]))
"""


def test_render_on_a_full_disk_writes_neither_image_nor_depth(tmp_path):
    out = subprocess.run(
        [sys.executable, "-c", RENDER_FULL, str(tmp_path / "a.png")], capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 2, out.stderr
    assert "cannot write" in out.stderr and "a.depth.npy" in out.stderr and "Traceback" not in out.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_report_on_a_half_written_run_says_so(ctx, tmp_path):
    from experiments.report import write_report

    folder = run_spec(parse_spec(SMALL.replace("frames = 3", "frames = 2")), tmp_path / "runs", ctx, progress=False)
    whole = write_report(folder, tmp_path / "whole").read_text()
    assert "INCOMPLETE" not in whole and "Incomplete" not in whole
    frames = pd.read_parquet(folder / "frames.parquet")
    gone = frames["config"].iloc[-1]
    frames[~((frames["config"] == gone) & (frames["frame"] == 1))].to_parquet(folder / "frames.parquet", index=False)
    text = write_report(folder, tmp_path / "part").read_text()
    assert text.startswith("# terrabench report: s (INCOMPLETE RUN)")
    assert f"1 of 4 frames are missing, in 1 of 2 configurations: {gone} (1 of 2 frames)" in text
    assert "INCOMPLETE RUN" in (tmp_path / "part" / "s" / "report.html").read_text()


def test_a_full_disk_during_a_run_is_one_message_and_the_journal_stays_whole(ctx, tmp_path, monkeypatch, capsys):
    import experiments.runner as runner

    spec = tmp_path / "s.toml"
    spec.write_text(SMALL)
    real_open = runner.Path.open
    calls = {"n": 0}

    def full_after_two(self, mode="r", *a, **k):
        if self.name == "frames.jsonl" and mode == "a":
            calls["n"] += 1
            if calls["n"] > 2:
                raise OSError(errno.ENOSPC, "No space left on device")
        return real_open(self, mode, *a, **k)

    monkeypatch.setattr(runner.Path, "open", full_after_two)
    rc = main(["run", str(spec), "--runs", str(tmp_path / "runs"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("error:") == 1 and "Traceback" not in err
    assert "disk full" in err and "frames.jsonl" in err
    lines = (tmp_path / "runs" / "s" / "frames.jsonl").read_text().splitlines()
    assert len(lines) == 2 and all("tiles_rows" in json.loads(line) for line in lines)  # whole lines
