"""The report on an adapting hybrid: starting models named apart, the convergence chart, GPU against CPU time."""

import pandas as pd
import pytest

from experiments.adapt_charts import NO_GPU_TIME, convergence_chart, gpu_cpu_chart, gpu_cpu_sentence
from experiments.charts import label_columns
from experiments.report import write_report
from experiments.runner import run_spec
from experiments.spec import parse_spec

SPEC = """
name = "adapt"
datasets = ["fbm"]
dataset_size = 129
flights = ["flyover"]
frames = 4
policies = ["raster", "raycast", "hybrid", "oracle"]
start_models = ["device", "fallback"]
sizes = ["160x90"]
repeats = 3
tile_size = 32
supersample = 1
flip = false
image_frames = [1]
"""


@pytest.fixture(scope="module")
def folder(ctx, tmp_path_factory):
    return run_spec(parse_spec(SPEC), tmp_path_factory.mktemp("runs"), ctx, progress=False)


def test_the_report_names_each_start_and_charts_convergence(folder, tmp_path):
    md = write_report(folder, tmp_path).read_text()
    out = md.replace("\n", " ")
    assert "hybrid/from-fallback" in out and "Hybrid adapted: yes" in out and "the uncalibrated fallback" in out
    assert "## Convergence" in md and (tmp_path / "adapt" / "convergence.png").stat().st_size > 10_000
    summary = md.split("## Summary")[1].split("##")[0]
    assert "| hybrid " in summary and "| hybrid/from-fallback " in summary
    assert "Adaptation (" in out and "prediction error" in out


def test_the_hybrids_predictions_are_recorded_per_frame_for_the_chart(folder):
    f = label_columns(pd.read_parquet(folder / "frames.parquet"))
    hy = f[f["policy"] == "hybrid"]
    assert set(hy["method"]) == {"hybrid", "hybrid/from-fallback"}
    assert hy["pred_ms"].notna().all() and (hy["pred_ms"] > 0).all() and (hy["draw_ms"] > 0).all()
    assert f.loc[f["policy"] == "raster", "pred_ms"].isna().all()


def test_no_gpu_chart_without_timer_queries_and_one_with_them(folder, tmp_path):
    f = label_columns(pd.read_parquet(folder / "frames.parquet"))
    if f["gpu_ms"].isna().all():  # a software rasterizer: nothing to tell apart
        assert gpu_cpu_chart(f, tmp_path) == [] and gpu_cpu_sentence(f) == NO_GPU_TIME
    g = f.copy()
    cpu = g["cpu_ms"].astype(float)  # GPU time twice the CPU's for ray casting, half for the rest
    g["gpu_ms"] = cpu.where(g["policy"] != "raycast", 2 * cpu).where(g["policy"] == "raycast", 0.5 * cpu)
    paths = gpu_cpu_chart(g, tmp_path)
    assert [p.name for p in paths] == ["gpu_vs_cpu.png", "gpu_vs_cpu.svg"] and paths[0].stat().st_size > 5_000
    words = gpu_cpu_sentence(g)
    assert "raycast 100 %" in words and "raster 0 %" in words


def test_no_convergence_chart_without_a_hybrid(folder, tmp_path):
    f = label_columns(pd.read_parquet(folder / "frames.parquet"))
    assert convergence_chart(f[f["policy"] != "hybrid"], tmp_path) == []
