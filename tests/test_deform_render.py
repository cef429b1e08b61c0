"""Every strategy draws the terrain as deformed at a time, after a sync, as a renderer made afresh on it would,
without cracks against the reference of the deformed heights."""

import numpy as np
import pytest
from edit_helpers import assert_draws_as_fresh, copy_terrain

from hybrid.camera.flight import preset
from hybrid.editing import TerrainEditor, replay
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.terrain.datasets import puget
from hybrid.terrain.deform import Uplift, Wave
from hybrid.terrain.edit_log import EditLog, LoggedDeformation, terrain_id

SIZE = (320, 180)


def _deformations(hf):
    ox, oy, _ = hf.origin
    return [
        (Wave((ox + 20480.0, oy + 20480.0), 9000.0, 400.0, 3000.0, 600.0), 0.0, 20.0),  # across 4 tiles
        (Uplift((ox + 10240.0, oy + 30000.0), 5000.0, 40.0), 2.0, 30.0),
    ]  # on a tile border


@pytest.mark.parametrize("policy", ["raster", "raster_gs", "raycast", "hybrid"])
def test_strategies_follow_deformations_across_tile_borders(ctx, policy):
    hf = copy_terrain(puget(size=257))
    fly = preset("flyover", hf, 6, *SIZE)
    views = [fly.view(1), fly.view(3)]
    r = Renderer(ctx, hf, policy, tile_size=64, adapt=False, reuse_choice=1)  # every frame planned: features compared
    ref = ReferenceRenderer(ctx, hf)
    editor = TerrainEditor(ctx, hf, r, ref)
    try:
        before = [r.render(v) for v in views]  # tiles resident before the deformation
        for d, start, end in _deformations(hf):
            editor.deform(d, start, end)
        for t in (1.0, 4.0, 9.5, 14.0):  # frames: the GPU heights only
            editor.step(t)
        report = editor.sync()
        assert report.tiles > 0 and any(report.refreshed.get(n, 0) for n in r.strategies)
        np.testing.assert_array_equal(hf.heights, editor.gpu.read())
        assert_draws_as_fresh(ctx, r, ref, views, before)
    finally:
        for x in (editor, ref, r):
            x.release()


def test_replaying_a_log_deforms_as_stepping_does(ctx):
    stepped, replayed = copy_terrain(puget(size=257)), copy_terrain(puget(size=257))
    log = EditLog(terrain_id(replayed), (), tuple(LoggedDeformation(s, e, d) for d, s, e in _deformations(replayed)))
    with TerrainEditor(ctx, replayed) as editor:
        reports = replay(editor, log, time=12.0)
    assert len(reports) == 1 and reports[0].ms["sync"] > 0
    with TerrainEditor(ctx, stepped) as editor:
        for d, s, e in _deformations(stepped):
            editor.deform(d, s, e)
        editor.step(12.0)
        editor.sync()
    np.testing.assert_array_equal(replayed.heights, stepped.heights)
    assert np.abs(replayed.heights - puget(size=257).heights).max() > 50.0


def test_render_replays_deformations_and_refuses_bad_ones_with_exit_2(tmp_path, ctx, capsys):
    import json

    from experiments.cli import main
    from experiments.scene_options import TerrainOptions
    from hybrid.terrain.edit_log import write_log

    args = ["render", "--dataset", "puget", "--size-samples", "129", "--size", "160x90", "--method", "raster"]
    terrain = TerrainOptions(dataset="puget", size_samples=129).load()
    ox, oy, _ = terrain.origin
    w, d = terrain.extent
    lift = LoggedDeformation(0.0, 10.0, Uplift((ox + w / 2, oy + d / 2), w / 4, 200.0))
    log = write_log(tmp_path / "d.jsonl", EditLog(terrain_id(terrain), (), (lift,)))
    assert main([*args, "--out", str(tmp_path / "plain.png")]) == 0
    assert main([*args, "--out", str(tmp_path / "lifted.png"), "--edit", str(log)]) == 0
    a, b = np.load(tmp_path / "plain.depth.npy"), np.load(tmp_path / "lifted.depth.npy")
    both = np.isfinite(a) & np.isfinite(b)
    assert np.count_nonzero(np.abs(a[both] - b[both]) > 10.0) > 100  # the uplift is in the frame
    header, good = log.read_text().splitlines()
    out = tmp_path / "out"
    out.mkdir()
    for change, words in (
        ({"rate": float("nan")}, "rate must be finite"),
        ({"start": 20.0}, "start and end must satisfy"),
        ({"radius": 0.0}, "radius must lie in"),
        ({"centre": [ox - 500.0, oy]}, "lies off terrain"),
    ):
        bad = tmp_path / "bad.jsonl"
        bad.write_text(header + "\n" + json.dumps({**json.loads(good), **change}) + "\n")
        assert main([*args, "--out", str(out / "a.png"), "--edit", str(bad)]) == 2, change
        err = capsys.readouterr().err
        assert words in err and "deformation 1" in err and "Traceback" not in err, err
        assert not any(out.iterdir())
