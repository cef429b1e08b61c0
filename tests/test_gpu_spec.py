"""The bundled gpu spec: Puget and its 16385² periodic extension named in a spec, the store prepared once into the
cache, run end to end through `terrabench run gpu` (kept cheap with --sizes and --frames), timing only, reported
without accuracy tables; GPU ms beside CPU ms in the summary wherever the GL timed it."""

import math

import numpy as np
import pandas as pd
import pytest

from experiments.cli import main
from experiments.report import summary_table
from experiments.spec import load_spec, parse_spec
from experiments.store_datasets import bundled_store
from hybrid.errors import TerrabenchError

PERIODIC = "puget@periodic16385"


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """A cache folder of this module's own (TERRABENCH_CACHE), so the Puget store is prepared here once."""
    folder = tmp_path_factory.mktemp("cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TERRABENCH_CACHE", str(folder))
        yield folder


def test_the_gpu_spec_pairs_both_sizes_datasets_flights_and_taus_without_accuracy():
    spec = load_spec("gpu")
    assert spec.sizes == ["1920x1080", "3840x2160"] and spec.datasets == ["puget", PERIODIC]
    assert spec.flights == ["flyover", "orbit", "dolly"] and spec.taus == [0.6667, 0.25]
    assert spec.policies == ["raster", "raster_gs", "raycast", "hybrid"] and not spec.accuracy
    assert len(spec.configs()) == 2 * 2 * 3 * 2 * 4 and spec.upload_budget_ms == 8.0
    cheap = load_spec("gpu", {"frames": 2, "sizes": ["160x90"]})
    assert cheap.frames == 2 and cheap.sizes == ["160x90"] and cheap.image_frames == [0]
    assert load_spec("default", {"frames": 3}).image_frames == [0]  # its frame 4 falls outside


@pytest.mark.parametrize(
    "text, match",
    [
        ('datasets = ["puget@periodic16000"]', "k x 1024 \\+ 1 samples"),
        ('datasets = ["puget@periodic1025"]', "k >= 2"),
        ('datasets = ["puget@periodic"]', "written STORE@periodicSIZE"),
        ('datasets = ["puget@periodicbig"]', "written STORE@periodicSIZE"),
        ('datasets = [{path = "puget@periodic2049", crs = "EPSG:32610"}]', "apply to files"),
        ('accuracy = "no"', "'accuracy' must be true or false"),
        ("accuracy = false\nvideo = true", "'video' shows each method beside the reference"),
    ],
)
def test_bad_store_datasets_and_accuracy_values_are_refused_by_name(text, match):
    with pytest.raises(TerrabenchError, match=match):
        parse_spec(text)


def test_bad_values_exit_2_from_the_command_line(tmp_path, capsys):
    spec = tmp_path / "s.toml"
    spec.write_text('datasets = ["puget@periodic3000"]\n')
    assert main(["run", str(spec), "--runs", str(tmp_path / "runs")]) == 2
    assert "puget's periodic extension must be k x 1024 + 1" in capsys.readouterr().err
    assert main(["run", "gpu", "--sizes", "160x90,wide", "--runs", str(tmp_path / "runs")]) == 2
    assert "--sizes" in capsys.readouterr().err
    assert main(["run", "stress", "--frames", "2", "--runs", str(tmp_path / "runs")]) == 2
    assert "stress spec takes no frames override" in capsys.readouterr().err


def test_the_bundled_store_is_prepared_once_and_renamed_whole(cache):
    path = bundled_store("puget", 128)
    assert path.parent == cache and path.name == "puget-t128-v1.store"
    assert [p.name for p in cache.iterdir()] == [path.name]  # no temporary folder left behind
    stamp = (path / "zarr.json").stat().st_mtime_ns
    assert bundled_store("puget", 128) == path and (path / "zarr.json").stat().st_mtime_ns == stamp


def _frames(gpu_ms):
    rows = [
        {
            "config": f"c-{p}",
            "dataset": "puget",
            "seed": 0,
            "flight": "orbit",
            "size": "160x90",
            "tau": 0.25,
            "reconstruction": "triangles",
            "full_res": "lean",
            "policy": p,
            "frame": k,
            "wall_ms": 10.0 + k,
            "wall_ms_repeats": [9.0 + k, 10.0 + k, 11.0 + k],
            "cpu_ms": 4.0,
            "gpu_ms": gpu_ms,
            "gpu_bytes": 1 << 20,
        }
        for p in ("raster", "raycast")
        for k in range(3)
    ]
    return pd.DataFrame(rows)


def test_the_summary_shows_gpu_ms_beside_cpu_ms_only_where_the_gl_timed_it():
    timed = summary_table(_frames(6.5))
    assert list(timed.columns[6:8]) == ["cpu_ms", "gpu_ms"] and (timed["gpu_ms"] == 6.5).all()
    assert "gpu_ms" not in summary_table(_frames(float("nan"))).columns


@pytest.mark.slow
def test_run_gpu_times_both_datasets_and_reports_without_accuracy(ctx, cache, tmp_path, capsys):
    """`terrabench run gpu` at 48x27 and 2 frames: every configuration's rows, finite times, the hybrid's tiles
    on the periodic extension, and a report that says accuracy was not measured instead of showing NaN."""
    from hybrid.gl.context import gl_info

    runs, reports = tmp_path / "runs", tmp_path / "reports"
    assert (
        main(
            [
                "run",
                "gpu",
                "--frames",
                "2",
                "--sizes",
                "48x27",
                "--runs",
                str(runs),
                "--report",
                "--reports",
                str(reports),
                "--quiet",
            ]
        )
        == 0
    )
    f = pd.read_parquet(runs / "gpu" / "frames.parquet")
    tiles = pd.read_parquet(runs / "gpu" / "tiles.parquet")
    assert not (runs / "gpu" / "errors.jsonl").exists() or not (runs / "gpu" / "errors.jsonl").read_text()
    assert len(f) == 48 * 2 and set(f["dataset"]) == {"puget", PERIODIC} and set(f["size"]) == {"48x27"}
    assert np.isfinite(f["wall_ms"]).all() and (f["wall_ms"] > 0).all()
    assert np.isfinite(f["cpu_ms"]).all() and (f["cpu_ms"] > 0).all()
    assert "psnr" not in f and "flip" not in f and not list((runs / "gpu" / "images").iterdir())
    llvmpipe = "llvmpipe" in gl_info(ctx).renderer
    assert f["gpu_ms"].isna().all() if llvmpipe else np.isfinite(f["gpu_ms"]).all()
    hyb = f[(f["policy"] == "hybrid") & (f["dataset"] == PERIODIC)]
    assert len(hyb) == 3 * 2 * 2 and (hyb["tiles"] > 0).all()
    assert (hyb["tiles_raster"] + hyb["tiles_raycast"] == hyb["tiles"]).all()
    mine = tiles[tiles["config"].isin(hyb["config"])]
    assert len(mine) == hyb["tiles"].sum()  # a tile row for every tile the hybrid drew
    big = f[f["dataset"] == PERIODIC].groupby("flight")["tiles"].max()
    small = f[f["dataset"] == "puget"].groupby("flight")["tiles"].max()
    assert (big > small).all() and (small <= 85).all()  # Puget has 85 tile places in tiles of 128
    text = (reports / "gpu" / "report.md").read_text()
    assert "accuracy not measured (accuracy = false)" in text
    summary = text.split("## Summary")[1].split("\n- ")[0]
    assert "psnr" not in summary and "nan" not in summary.lower() and "cpu_ms" in summary
    assert ("gpu_ms" in summary) != llvmpipe
    html = (reports / "gpu" / "report.html").read_text()
    assert "accuracy not measured" in html and ">NaN<" not in html
    assert math.isfinite(summary_table(f)["median_ms"].max())
