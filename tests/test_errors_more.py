"""Right or refused at every size: memory bounds of synthetic terrain, and one clear message (exit code 2,
no traceback, nothing half written) for corrupt runs, bad schedulers, missing files, full disks and more."""

import errno
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from experiments.cli import main
from hybrid import atomic
from hybrid.errors import TerrabenchError
from hybrid.terrain import datasets
from hybrid.tiles import bounds


def _fails(argv, capsys, *needles):
    """Run the CLI; it must exit 2 with one error line holding every needle and no traceback."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("terrabench: error:") == 1, err
    for needle in needles:
        assert needle in err, err
    return err


@pytest.mark.parametrize("name", ["fbm", "ridged", "staircase", "ridges", "cliff"])
def test_synthetic_bands_equal_the_whole_grid(monkeypatch, name):
    whole = datasets.get_dataset(name, size=301, seed=3).heights
    monkeypatch.setattr(datasets, "BAND_SAMPLES", 3000)  # ten rows a band: many bands, two passes
    banded = datasets.get_dataset(name, size=301, seed=3).heights
    assert banded.dtype == np.float32 and np.array_equal(banded, whole)


def test_pyramid_bounds_blocks_equal_the_whole_grid(monkeypatch, synthetic):
    from hybrid.tiles.pyramid import TilePyramid

    hf = synthetic("fbm", size=257)
    monkeypatch.setattr(bounds, "BLOCK_CELLS", 1 << 12)  # one block
    one = TilePyramid(hf, 16)
    monkeypatch.setattr(bounds, "BLOCK_CELLS", 8)  # blocks smaller than every tile above level 0
    many = TilePyramid(hf, 16)
    for level in range(one.max_level + 1):
        for a, b in ((one._zmax, many._zmax), (one._zmin, many._zmin), (one._err, many._err)):
            assert np.array_equal(a[level], b[level])
    assert one._err[one.max_level].max() > 0


def test_too_large_synthetic_is_refused_at_once_with_the_numbers(capsys):
    t0 = time.perf_counter()
    _fails(
        ["info", "--dataset", "fbm", "--size-samples", "16386", "--no-gl"],
        capsys,
        "16386",
        "16385",
        "1.4 GiB",
        "terrabench prepare --synthetic SIZE --out STORE",
    )
    assert time.perf_counter() - t0 < 1.0


def test_accepted_synthetic_size_stays_within_its_stated_peak():
    size = 2049
    if not Path("/proc/self/status").exists():
        pytest.skip("needs /proc/self/status (VmHWM)")
    # VmHWM, not ru_maxrss: Linux keeps ru_maxrss across execve, so a child would report this process's peak
    code = (
        "import re, sys\nfrom pathlib import Path\nfrom experiments.cli import main\n"
        f"rc = main(['info', '--dataset', 'fbm', '--size-samples', '{size}', '--no-gl'])\n"
        "hwm = re.search(r'VmHWM:\\s+(\\d+) kB', Path('/proc/self/status').read_text())\n"
        "print(int(hwm[1]) * 1024, file=sys.stderr)\n"
        "raise SystemExit(rc)"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        check=False,
        capture_output=True,
        text=True,
        timeout=120,
        cwd=Path(__file__).resolve().parents[1],
    )
    assert done.returncode == 0, done.stderr
    peak = int(done.stderr.strip().splitlines()[-1])
    assert peak <= datasets.synthetic_peak_bytes(size), (peak, datasets.synthetic_peak_bytes(size))


def _run_folder(tmp_path, frames: bytes | None = None, spec: str = '{"name": "r"}'):
    import pandas as pd

    run = tmp_path / "runs" / "r"
    run.mkdir(parents=True)
    if frames is None:
        pd.DataFrame({"frame": [0]}).to_parquet(run / "frames.parquet")
    else:
        (run / "frames.parquet").write_bytes(frames)
    (run / "spec.json").write_text(spec)
    (run / "env.json").write_text("{}")
    return run


@pytest.mark.parametrize(
    "frames, spec, needles",
    [
        (b"PAR1 torn off", '{"name": "r"}', ["frames.parquet", "corrupt", "Parquet"]),
        (None, '{"name": "r", "frames": [', ["spec.json", "corrupt", "JSON"]),
        (None, "\x00\xff", ["spec.json", "corrupt"]),
    ],
)
def test_report_of_a_corrupt_run_folder_is_one_message(tmp_path, capsys, frames, spec, needles):
    run = _run_folder(tmp_path, frames, spec)
    reports = tmp_path / "reports"
    reports.mkdir()
    _fails(["report", run, "--reports", reports], capsys, *needles)
    assert not any(reports.iterdir())


def test_scheduler_that_is_not_an_address_is_one_message(tmp_path, capsys):
    pytest.importorskip("distributed")
    runs = tmp_path / "runs"
    _fails(
        ["run", "tiny", "--runs", runs, "--scheduler", "notanaddress"],
        capsys,
        "'notanaddress'",
        "not a Dask scheduler address",
    )
    assert not (runs / "tiny").exists()


def test_unreachable_scheduler_gives_up_within_its_timeout(tmp_path, capsys):
    pytest.importorskip("distributed")
    from experiments.cluster import CONNECT_TIMEOUT_S

    assert CONNECT_TIMEOUT_S <= 10
    t0 = time.perf_counter()
    _fails(
        ["run", "tiny", "--runs", tmp_path, "--scheduler", "tcp://127.0.0.1:1", "--scheduler-timeout", "1"],
        capsys,
        "cannot reach the Dask scheduler at 'tcp://127.0.0.1:1' within 1 s",
        "--scheduler-timeout",
    )
    assert time.perf_counter() - t0 < 6
    assert not (tmp_path / "tiny").exists()


@pytest.mark.parametrize(
    "dataset, needles",
    [
        ("missing.tif", ["missing.tif", "no such file"]),
        ("nowhere", ["unknown dataset 'nowhere'"]),
        ("LOOP", ["symlink loop"]),
        ("store@periodic4097", ["store", "no such file"]),
    ],
)
def test_spec_with_a_missing_dataset_is_refused_before_its_run_folder(tmp_path, capsys, dataset, needles):
    loop = tmp_path / "loop.tif"
    loop.symlink_to(loop)
    spec = tmp_path / "s.toml"
    spec.write_text(f'name = "s"\ndatasets = ["{dataset.replace("LOOP", str(loop))}"]\nframes = 2\n')
    runs = tmp_path / "runs"
    _fails(["run", spec, "--runs", runs, "--quiet"], capsys, *needles)
    assert not (runs / "s").exists()


@pytest.mark.parametrize("name", ["loop", "loop.tif", "loop.npy"])
def test_symlink_loop_as_a_dataset_is_named(tmp_path, capsys, name):
    loop = tmp_path / name
    loop.symlink_to(loop)
    _fails(["info", "--dataset", loop, "--no-gl"], capsys, str(loop), "symlink loop")
    _fails(["render", "--dataset", loop, "--out", tmp_path / "a.png"], capsys, "symlink loop")
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def _enospc(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def _short_write(*args, **kwargs):
    raise OSError("14400 requested and 10208 written")  # NumPy's tofile: no errno


@pytest.mark.parametrize(
    "owner, attr, writer, name",
    [
        (np, "save", lambda p: atomic.save_npy(p, np.zeros(3600, np.float32)), "a.npy"),
        (Image.Image, "save", lambda p: atomic.save_png(p, np.zeros((4, 4, 3), np.uint8)), "a.png"),
        (pd.DataFrame, "to_parquet", lambda p: atomic.write_parquet(p, pd.DataFrame({"a": [1]})), "a.parquet"),
        (Path, "write_text", lambda p: atomic.write_json(p, {"a": 1}), "a.json"),
        (Path, "write_text", lambda p: atomic.write_text(p, "# report"), "report.md"),
    ],
)
@pytest.mark.parametrize("fail", [_enospc, _short_write])
def test_every_writer_names_a_full_disk(tmp_path, monkeypatch, owner, attr, writer, name, fail):
    monkeypatch.setattr(owner, attr, fail)
    with pytest.raises(
        TerrabenchError, match=f"(disk full while writing|cannot write) {tmp_path / name}.*nothing was written"
    ) as exc:
        writer(tmp_path / name)
    assert "disk full" in str(exc.value)
    assert not any(tmp_path.iterdir())  # no partial file, no temporary


def test_render_on_a_full_disk_is_one_message_and_writes_nothing(tmp_path, capsys, ctx, monkeypatch):
    monkeypatch.setattr(np, "save", _short_write)
    _fails(
        ["render", "--dataset", "fbm", "--size-samples", "65", "--size", "96x64", "--out", tmp_path / "a.png"],
        capsys,
        "disk full or a file size limit",
        "a.depth.npy",
    )
    assert not any(tmp_path.iterdir())


def _dead_pid() -> int:
    done = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], check=True, capture_output=True, text=True
    )
    return int(done.stdout)


def _temps(folder, pid_dead, pid_live):
    """A dead writer's and a live writer's temporaries in folder, as atomic_path names them."""
    dead = [folder / f".tiles.parquet.{pid_dead}.tmp.parquet", folder / f".a.depth.npy.{pid_dead}.tmp.npy"]
    live = folder / f".frames.parquet.{pid_live}.tmp.parquet"
    for p in dead + [live]:
        p.write_bytes(b"partial")
    return dead, live


def test_dead_writers_temps_go_and_a_live_writers_stay(tmp_path):
    with subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"]) as live_writer:
        try:
            dead, live = _temps(tmp_path, _dead_pid(), live_writer.pid)
            (tmp_path / ".notes.txt").write_text("not a temporary")
            assert sorted(atomic.remove_stale_temps(tmp_path)) == sorted(dead)
            assert live.exists() and (tmp_path / ".notes.txt").exists()
            assert not any(p.exists() for p in dead)
        finally:
            live_writer.kill()


def test_render_and_resumed_run_remove_dead_writers_temps(tmp_path, ctx):
    dead, live = _temps(tmp_path, _dead_pid(), os.getpid())
    assert (
        main(
            ["render", "--dataset", "fbm", "--size-samples", "65", "--size", "96x64", "--out", str(tmp_path / "a.png")]
        )
        == 0
    )
    assert not any(p.exists() for p in dead) and live.exists()
    run = tmp_path / "runs" / "tiny"
    (run / "images").mkdir(parents=True)
    dead, _ = _temps(run, _dead_pid(), 1)
    dead_image = run / "images" / f".ref-0-f0.png.{_dead_pid()}.tmp.png"
    dead_image.write_bytes(b"partial")
    assert main(["run", "tiny", "--runs", str(tmp_path / "runs"), "--frames", "1", "--quiet"]) == 0
    assert not any(p.exists() for p in dead + [dead_image])
    assert (run / "frames.parquet").exists()


def test_geographic_crs_on_a_metre_grid_says_so(tmp_path, capsys):
    rasterio = pytest.importorskip("rasterio")
    from rasterio.transform import from_origin

    p = tmp_path / "utm.tif"
    with rasterio.open(
        p,
        "w",
        driver="GTiff",
        height=16,
        width=16,
        count=1,
        dtype="float32",
        crs="EPSG:32610",
        transform=from_origin(500000, 5000000, 30, 30),
    ) as d:
        d.write(np.ones((16, 16), np.float32), 1)
    _fails(
        ["info", p, "--crs", "EPSG:4326", "--no-gl"],
        capsys,
        str(p),
        "does not fit the CRS WGS 84 (EPSG:4326)",
        "degrees",
        "x 500000",
        "--spacing",
    )
    assert main(["info", str(p), "--no-gl"]) == 0  # its own CRS converts as before


def test_prepare_takes_the_files_render_takes(tmp_path, capsys):
    np.save(tmp_path / "x.npy", np.random.default_rng(0).uniform(0, 100, (65, 65)).astype(np.float32))
    (np.arange(33 * 33, dtype="<u2") % 500).reshape(33, 33).tofile(tmp_path / "x.raw")
    assert main(["prepare", str(tmp_path / "x.npy"), "--spacing", "10", "--out", str(tmp_path / "s"), "--quiet"]) == 0
    assert (
        main(
            [
                "prepare",
                str(tmp_path / "x.raw"),
                "--raw-shape",
                "33x33",
                "--raw-dtype",
                "<u2",
                "--spacing",
                "10",
                "--out",
                str(tmp_path / "r"),
                "--quiet",
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert main(["info", str(tmp_path / "s"), "--no-gl"]) == 0
    assert "65 x 65" in capsys.readouterr().out
    _fails(["prepare", tmp_path / "x.npy", "--out", tmp_path / "t"], capsys, "x.npy", "--spacing")
    assert not (tmp_path / "t").exists()


def test_a_closed_stdout_ends_quietly(tmp_path):
    """`terrabench render ... | head -0`: the reader is gone before the first line; no traceback."""
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "experiments",
            "render",
            "--dataset",
            "puget",
            "--size-samples",
            "65",
            "--size",
            "32x16",
            "--out",
            str(tmp_path / "a.png"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert "Traceback" not in err and "BrokenPipe" not in err, err
