"""An edit run whose programme names a deformation: every method follows the wave frame by frame, as accurate
against the reference of the deformed heights as on the static terrain, and its edit log replays the terrain."""

import numpy as np
import pandas as pd
import pytest
from edit_helpers import copy_terrain, tiny_edit_spec

from experiments.edit_deform import DeformProgramme
from experiments.edit_run import run_edit_spec
from experiments.edit_spec import spec_deformation
from hybrid.camera.flight import get_flight
from hybrid.editing import TerrainEditor, replay
from hybrid.reference import ReferenceRenderer
from hybrid.terrain.edit_log import read_log

POLICIES = ["raster", "raycast"]
WAVE = DeformProgramme(
    "wave", (0.75, 0.7), 6000.0, amplitude=300.0, wavelength=4000.0, speed=2000.0, end=3.0, seconds_per_frame=1.0
)  # ahead of the flyover's eye at frame 1, which runs from (0.1, 0.15) to (0.9, 0.85) looking north-east


@pytest.fixture(scope="module")
def run(ctx, tmp_path_factory):
    spec = tiny_edit_spec(
        "deform-tiny",
        {"radii": (1500.0,), "edits_per_frame": 0, "particles": 64, "deformation": WAVE},
        image_frames=[1],
        policies=POLICIES,
        flip=False,
    )
    return spec, run_edit_spec(spec, tmp_path_factory.mktemp("runs"), ctx, progress=False)


def test_every_method_follows_the_deformation_as_accurately_as_static_terrain(run):
    _, folder = run
    f = pd.read_parquet(folder / "frames.parquet")
    e, s = f[f["editing"]], f[~f["editing"]]
    assert len(e) == len(s) == len(POLICIES) * 3
    assert (e["edits"] == 0).all() and e["update_deform_ms"].gt(0).all() and e["update_sync_ms"].gt(0).all()
    assert e["edit_tiles"].gt(0).all() and e["edit_refreshed"].gt(0).all()
    assert s["update_ms"].eq(0).all()
    assert int(f["crack_px"].max()) == 0
    assert f["coverage_mismatch"].max() < 0.01 and f["depth_rel_median"].max() < 0.02


def test_the_deformed_frames_differ_from_the_static_ones(run):
    _, folder = run
    images = folder / "images"
    for stem in ["ref-{}-f1"] + [f"puget-s0-flyover-96x54-tau0.6667-{p}-{{}}-f1" for p in POLICIES]:
        static, moved = (np.load(images / f"{stem.format(v)}.depth.npy") for v in ("static", "r1500m"))
        both = np.isfinite(static) & np.isfinite(moved)
        assert np.count_nonzero(np.abs(static[both] - moved[both]) > 1.0) > 20, stem


def test_the_log_replays_the_deformed_terrain_where_the_wave_acts(ctx, run):
    spec, folder = run
    hf = spec.terrain()
    log = read_log(folder / "edits-r1500m.jsonl")
    assert [d.deformation for d in log.deformations] == [spec_deformation(spec, hf)]
    replayed = copy_terrain(hf)
    with TerrainEditor(ctx, replayed) as editor:
        replay(editor, log, time=WAVE.time(1))  # frame 1's clock time
    (cx, cy), (ys, xs) = spec_deformation(spec, hf).centre, np.indices(hf.heights.shape)
    d = np.hypot(hf.origin[0] + xs * hf.spacing_x - cx, hf.origin[1] + ys * hf.spacing_y - cy)
    change = np.abs(replayed.heights - hf.heights)
    assert change[d < WAVE.radius].max() > 50.0 and change[d > WAVE.radius + hf.spacing_x].max() == 0.0
    view = get_flight(spec.flight, hf, frames=spec.frames, width=96, height=54).views()[1]
    with ReferenceRenderer(ctx, replayed) as ref:
        again = ref.render(view, supersample=spec.supersample).distance
    np.testing.assert_array_equal(again, np.load(folder / "images" / "ref-r1500m-f1.depth.npy"))
