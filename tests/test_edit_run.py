"""An edit run end to end at a tiny size: every method follows the same edits, its tables, 0 cracks, the report."""

import numpy as np
import pandas as pd
import pytest
from edit_helpers import tiny_edit_spec

from experiments.edit_run import run_edit_spec
from experiments.report import write_run_report
from hybrid.terrain.edit_log import check_log, read_log

POLICIES = {"raster", "raster_gs", "raycast", "hybrid"}


@pytest.fixture(scope="module")
def run(ctx, tmp_path_factory):
    spec = tiny_edit_spec(
        "edit-tiny",
        {"radii": (1500.0, 3000.0), "strength": 300.0, "particles": 512},
        image_frames=[2],
        policies=sorted(POLICIES),
    )
    base = tmp_path_factory.mktemp("runs")
    return spec, run_edit_spec(spec, base, ctx, progress=False)


def test_tables_hold_updates_frames_particles_and_accuracy(run):
    spec, folder = run
    f = pd.read_parquet(folder / "frames.parquet")
    assert len(f) == len(POLICIES) * 3 * 3 and set(f["policy"]) == POLICIES
    for col in (
        "wall_ms",
        "wall_ms_repeats",
        "update_ms",
        "update_brush_ms",
        "update_pyramid_ms",
        "edits",
        "edit_tiles",
        "particles",
        "particles_ms",
        "particles_step_ms",
        "particles_draw_ms",
        "particles_gpu_ms",
        "crack_px",
        "coverage_mismatch",
        "depth_rel_median",
        "flip",
        "gpu_bytes",
        "edit_gpu_bytes",
        "editing",
        "edit_radius",
    ):
        assert col in f, col
    e, s = f[f["editing"]], f[~f["editing"]]
    assert (e["edits"] == 1).all() and (s["edits"] == 0).all() and (s["update_ms"] == 0).all()
    assert e["update_ms"].gt(0).all() and e["update_brush_ms"].gt(0).all()
    assert e.loc[e["policy"] != "raycast", "update_raster_nodes_ms"].gt(0).all()
    assert e.loc[e["policy"] == "raycast", "update_raycast_ms"].gt(0).all()
    # the same edits at the same frames for every method: the same tiles touched
    assert (e.groupby(["edit_radius", "frame"])["edit_tiles"].nunique() == 1).all()
    assert f["particles"].eq(512).all() and f["particles_ms"].gt(0).all() and f["particles_bytes"].gt(0).all()
    assert f["wall_ms"].gt(0).all() and all(len(r) == spec.repeats for r in f["wall_ms_repeats"])
    assert int(f["crack_px"].max()) == 0  # no crack after the edits
    assert f["coverage_mismatch"].max() < 0.01 and f["depth_rel_median"].max() < 0.02
    assert (folder / "tiles.parquet").exists()


def test_the_edits_are_in_view_and_the_reference_follows_them(run):
    _, folder = run
    static, edited = (np.load(folder / "images" / f"ref-{v}-f2.depth.npy") for v in ("static", "r3000m"))
    both = np.isfinite(static) & np.isfinite(edited)
    assert np.count_nonzero(np.abs(static[both] - edited[both]) > 1.0) > 20
    for policy in POLICIES:
        assert (folder / "images" / f"puget-s0-flyover-96x54-tau0.6667-{policy}-r3000m-f2.png").exists()


def test_each_radius_has_an_edit_log_that_replays_on_the_terrain(run):
    spec, folder = run
    hf = spec.terrain()
    for r in spec.edit.radii:
        log = check_log(read_log(folder / f"edits-r{r:g}m.jsonl"), hf)
        assert [e.frame for e in log.edits] == [0, 1, 2] and {e.brush.radius for e in log.edits} == {r}


def test_a_finished_run_resumes_without_redoing(run, ctx):
    spec, folder = run
    before = (folder / "frames.jsonl").read_text()
    run_edit_spec(spec, folder.parent, ctx, progress=False)
    assert (folder / "frames.jsonl").read_text() == before


def test_report_reads_which_method_a_dynamic_scene_favours(run, tmp_path):
    _, folder = run
    md = write_run_report(folder, tmp_path)
    text = md.read_text()
    assert "a dynamic scene on" in text
    assert "favours **" in text and "0 crack pixels in any edited frame" in text
    assert "Frame-to-frame colour change over the reference's" in text and "change_ratio" in text
    for png in ("update_vs_radius.png", "frame_on_off.png", "images.png"):
        assert (md.parent / png).stat().st_size > 0 and f"]({png})" in text
    html = md.with_suffix(".html").read_text()
    assert "<table" in html and "update_vs_radius.png" in html


def test_edits_change_each_method_between_frames_as_the_reference_changes(run):
    """The colour change from one frame to the next over the reference's (of the same edited heights) is near 1
    for every method and variant: an edit that made a method pop would raise it; the report reads it."""
    _, folder = run
    f = pd.read_parquet(folder / "frames.parquet")
    assert f.loc[f["frame"] == 0, "change_ratio"].isna().all()
    later = f[f["frame"] > 0]
    assert np.isfinite(later["change_ratio"]).all() and np.isfinite(later["error_flicker"]).all()
    assert later["change_ratio"].between(0.95, 1.05).all(), later[["policy", "edit_radius", "frame", "change_ratio"]]
