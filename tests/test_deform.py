"""Deformations driven by time: checked by name, the GPU's heights at a time equal the CPU's, the same frames on
every run whatever the steps before, logged and replayed, and every strategy following them without cracks."""

import json

import numpy as np
import pytest

from hybrid.errors import TerrabenchError
from hybrid.terrain.datasets import get_dataset
from hybrid.terrain.deform import MAX_SECONDS, Uplift, Wave, check_deformation, compose, deform_params, displacement
from hybrid.terrain.edit_log import EditLog, LoggedDeformation, LoggedEdit, read_log, terrain_id, write_log
from hybrid.terrain.edits import Raise, Smooth, Window, apply_brush, brush_params


def _tol(h):
    """Absolute tolerance (m) of GPU against CPU heights: a few float32 steps at the heights' magnitude (the GPU's
    sine differs in its last bits, so a sum may round the other way) and the sine's error on 20 m."""
    return 4 * float(np.spacing(np.float32(np.abs(h).max()))) + 1e-4


WAVE = Wave((900.0, 900.0), 700.0, 20.0, 200.0, 50.0)
UPLIFT = Uplift((1290.0, 690.0), 600.0, 0.5)  # centred on sample (23, 43)


@pytest.fixture
def hf():
    return get_dataset("fbm", 65)  # 64 cells of 30 m


@pytest.fixture(params=[None, 24], ids=["one-texture", "blocks"])
def limit(request, ctx):
    """The GL's texture size limit as the editor sees it: its own, or 24 (the heights in 3x3 blocks)."""
    from hybrid.gl.context import context_extra

    if request.param is not None:
        context_extra(ctx)["max_texture_size"] = request.param
    yield request.param
    context_extra(ctx).pop("max_texture_size", None)


@pytest.mark.parametrize(
    ("d", "start", "end", "words"),
    [
        (Wave((900.0, 900.0), 0.0, 20.0, 200.0, 50.0), 0, 10, "radius must lie in"),
        (Wave((-50.0, 900.0), 300.0, 20.0, 200.0, 50.0), 0, 10, "lies off terrain"),
        (Wave((900.0, 900.0), 300.0, float("nan"), 200.0, 50.0), 0, 10, "amplitude must be finite"),
        (Wave((900.0, 900.0), 300.0, 20.0, 0.0, 50.0), 0, 10, "wavelength must be > 0"),
        (Wave((900.0, 900.0), 300.0, 20.0, 200.0, -1.0), 0, 10, "speed must be > 0"),
        (Uplift((900.0, 900.0), 300.0, 1.0), 5, 5, "start and end must satisfy"),
        (Uplift((900.0, 900.0), 300.0, 1.0), 0, MAX_SECONDS * 2, "start and end must satisfy"),
        (Uplift((900.0, 900.0), 300.0, 1e6), 0, 100, "displacement"),
        (Uplift((900.0, 900.0), 300.0, float("inf")), 0, 100, "rate must be finite"),
    ],
)
def test_bad_deformations_are_refused_by_name(hf, d, start, end, words):
    with pytest.raises(TerrabenchError, match=words):
        check_deformation(d, hf, start, end)


def test_displacements_start_at_zero_stay_in_their_disc_and_freeze_after_their_end(hf):
    full = Window(0, hf.rows, 0, hf.cols)
    p, q = deform_params(WAVE, hf, 2.0, 12.0), deform_params(UPLIFT, hf, 0.0, 20.0)
    assert not displacement(p, full, 2.0).any() and not displacement(q, full, 0.0).any()
    wave = displacement(p, full, 6.0)  # 4 s in: the front 200 m from the centre
    i, j = np.indices(wave.shape)
    d = np.hypot(j * 30.0 - 900.0, i * 30.0 - 900.0)
    assert np.abs(wave).max() > 5.0 and not wave[d >= 200.0].any()
    np.testing.assert_array_equal(displacement(p, full, 12.0), displacement(p, full, 500.0))
    up = displacement(q, full, 10.0)
    assert (
        up.max() == pytest.approx(5.0, rel=1e-6) and not up[np.hypot(j * 30.0 - 1290.0, i * 30.0 - 690.0) >= 600].any()
    )


def test_gpu_heights_at_each_step_equal_the_cpu_composition(ctx, hf, limit):
    from hybrid.editing import TerrainEditor

    base = hf.heights.copy()
    full = Window(0, hf.rows, 0, hf.cols)
    with TerrainEditor(ctx, hf) as editor:
        assert len(editor.gpu.blocks) == (1 if limit is None else 9)
        editor.deform(WAVE, 1.0, 30.0)
        editor.deform(UPLIFT, 0.0, 20.0)
        params = editor.deforms.params
        for t in (0.5, 3.0, 7.25, 11.0, 19.5, 40.0):
            wins = editor.step(t)
            got = editor.gpu.read()
            np.testing.assert_allclose(got, compose(base, params, t, full), rtol=0, atol=_tol(base))
            outside = np.ones(got.shape, bool)
            for w in wins:
                outside[w.slices()] = False
            np.testing.assert_array_equal(got[outside], base[outside])  # the windows only
        assert editor.step(41.0) == []  # both ended: nothing moves
        np.testing.assert_array_equal(hf.heights, base)  # the CPU copy waits for sync
        report = editor.sync()
        np.testing.assert_array_equal(hf.heights, editor.gpu.read())
        assert report.ms["sync"] > 0 and not report.window.empty


def test_the_same_time_gives_the_same_heights_whatever_the_steps_before(ctx):
    from hybrid.editing import TerrainEditor

    out = []
    for times in ((0.0, 1.0, 2.0, 3.0, 4.0, 9.5), (9.5,), (20.0, 3.0, 9.5)):
        hf = get_dataset("fbm", 65)
        with TerrainEditor(ctx, hf) as editor:
            editor.deform(WAVE, 0.0, 30.0)
            editor.deform(UPLIFT, 2.0, 20.0)
            for t in times:
                editor.step(t)
            out.append(editor.gpu.read())
    for other in out[1:]:
        np.testing.assert_array_equal(other, out[0])


def test_a_brush_under_deformations_edits_the_base(ctx, hf, limit):
    from hybrid.editing import TerrainEditor

    base = hf.heights.copy()
    brushes = [Raise((1000.0, 800.0), 400.0, 30.0), Smooth((800.0, 1000.0), 300.0, 1.0)]  # across block borders
    with TerrainEditor(ctx, hf) as editor:
        editor.deform(WAVE, 0.0, 30.0)
        editor.step(5.0)
        for b in brushes:
            editor.apply(b)
            apply_brush(base, brush_params(b, hf))
        np.testing.assert_array_equal(editor.deforms.read_base(), base)
        want = compose(base, editor.deforms.params, 5.0, Window(0, hf.rows, 0, hf.cols))
        np.testing.assert_allclose(editor.gpu.read(), want, rtol=0, atol=_tol(base))
        editor.step(8.0)
        np.testing.assert_allclose(
            editor.gpu.read(),
            compose(base, editor.deforms.params, 8.0, Window(0, hf.rows, 0, hf.cols)),
            rtol=0,
            atol=_tol(base),
        )


def test_deformations_round_trip_through_the_log_and_bad_lines_are_refused(tmp_path, hf):
    log = EditLog(
        terrain_id(hf),
        (LoggedEdit(0, Raise((900.0, 900.0), 300.0, 5.0)),),
        (LoggedDeformation(1.0, 30.0, WAVE), LoggedDeformation(0.0, 20.0, UPLIFT)),
    )
    path = write_log(tmp_path / "d.jsonl", log)
    assert read_log(path) == log
    header = path.read_text().splitlines()[0]
    good = json.loads(path.read_text().splitlines()[2])
    for bad, words in (
        ({**good, "speed": "fast"}, "line 2: speed must be a number"),
        ({k: v for k, v in good.items() if k != "end"}, "line 2: a wave deformation has keys"),
        ({**good, "deformation": "quake"}, "line 2: deformation must be one of wave, uplift"),
    ):
        p = tmp_path / "bad.jsonl"
        p.write_text(header + "\n" + json.dumps(bad) + "\n")
        with pytest.raises(TerrabenchError, match=words):
            read_log(p)
