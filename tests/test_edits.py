"""Terrain edits: brushes checked against the terrain, their CPU reference, and the edit log."""

import json

import numpy as np
import pytest

from hybrid.errors import TerrabenchError
from hybrid.terrain.datasets import get_dataset
from hybrid.terrain.edit_log import EditLog, LoggedEdit, check_log, read_log, terrain_id, write_log
from hybrid.terrain.edits import Crater, Flatten, Raise, Smooth, Window, apply_brush, brush_params, check_brush, touched
from hybrid.terrain.heightfield import HeightField


@pytest.fixture
def hf():
    return get_dataset("fbm", 65)  # 64 x 30 m = 1920 m a side, origin 0


def _slow(brush, hf):
    """Each brush from its definition, sample by sample in float64 (what the vectorised float32 one must match)."""
    h = hf.heights.astype(np.float64)
    out = h.copy()
    for i in range(hf.rows):
        for j in range(hf.cols):
            d2 = (j * hf.spacing_x - brush.centre[0]) ** 2 + (i * hf.spacing_y - brush.centre[1]) ** 2
            t = d2 / brush.radius**2
            if t >= 1:
                continue
            w = (1 - t) ** 2
            if isinstance(brush, Raise):
                out[i, j] = h[i, j] + brush.strength * w
            elif isinstance(brush, Flatten):
                out[i, j] = h[i, j] + (brush.height - h[i, j]) * brush.strength * w
            elif isinstance(brush, Smooth):
                rr = np.clip([i - 1, i, i + 1], 0, hf.rows - 1)
                cc = np.clip([j - 1, j, j + 1], 0, hf.cols - 1)
                out[i, j] = h[i, j] + (h[np.ix_(rr, cc)].mean() - h[i, j]) * brush.strength * w
            else:
                q = np.sqrt(t)
                bowl = -brush.strength * (1 - q * q / 0.49) if q < 0.7 else 0.0
                u = (q - 0.7) / 0.3
                rim = 0.3 * brush.strength * (1 - u * u) ** 2 if abs(q - 0.7) < 0.3 else 0.0
                out[i, j] = h[i, j] + bowl + rim
    return out


@pytest.mark.parametrize(
    "brush",
    [
        Raise((900.0, 700.0), 400.0, 50.0),
        Raise((0.0, 1920.0), 300.0, -80.0),
        Flatten((1000.0, 1000.0), 500.0, 0.8, 200.0),
        Smooth((960.0, 960.0), 600.0, 1.0),
        Crater((1500.0, 400.0), 450.0, 120.0),
    ],
)
def test_cpu_brush_matches_its_definition_and_stays_in_window(hf, brush):
    want = _slow(brush, hf)
    h = hf.heights.copy()
    win = apply_brush(h, brush_params(brush, hf))
    assert not win.empty
    np.testing.assert_allclose(h, want, rtol=0, atol=2e-3 * max(1.0, abs(brush.strength)))
    outside = np.ones(h.shape, bool)
    outside[win.slices()] = False
    assert np.array_equal(h[outside], hf.heights[outside])  # nothing beyond the window moves
    assert np.abs(h - hf.heights).max() > 0.1


def test_window_is_the_radius_in_samples(hf):
    p = brush_params(Raise((900.0, 600.0), 95.0, 1.0), hf)  # 3.17 samples east-west and north-south
    win = touched(p, hf.rows, hf.cols)
    assert (win.i0, win.i1, win.j0, win.j1) == (17, 24, 27, 34)


def test_raise_with_falloff_is_seamless_at_the_rim(hf):
    h = hf.heights.copy()
    apply_brush(h, brush_params(Raise((960.0, 960.0), 600.0, 100.0), hf))
    d = h.astype(np.float64) - hf.heights
    assert d[32, 32] == pytest.approx(100.0, abs=1e-3)
    assert d[32, 32 + 19] == pytest.approx(100.0 * (1 - 0.9025) ** 2, abs=1e-3)  # 570 m of 600
    assert d[32, 32 + 20] == 0.0 and d[32, 32 - 20] == 0.0  # the rim itself: weight 0


@pytest.mark.parametrize(
    "brush, words",
    [
        (Raise((100.0, 100.0), 0.0, 1.0), "radius"),
        (Raise((100.0, 100.0), -5.0, 1.0), "radius"),
        (Raise((100.0, 100.0), 5000.0, 1.0), "larger extent"),
        (Raise((100.0, 100.0), 50.0, float("nan")), "strength"),
        (Raise((-10.0, 100.0), 50.0, 1.0), "off terrain"),
        (Raise((100.0, 2000.0), 50.0, 1.0), "off terrain"),
        (Smooth((100.0, 100.0), 50.0, 1.5), "[0, 1]"),
        (Flatten((100.0, 100.0), 50.0, 0.5, float("inf")), "height"),
        (Raise((float("nan"), 100.0), 50.0, 1.0), "centre x"),
    ],
)
def test_bad_brushes_are_refused_by_name(hf, brush, words):
    with pytest.raises(TerrabenchError, match="brush") as info:
        check_brush(brush, hf)
    assert words in str(info.value)


def _log(hf):
    return EditLog(
        terrain_id(hf),
        (
            LoggedEdit(0, Raise((900.0, 700.0), 400.0, 50.0)),
            LoggedEdit(2, Flatten((1000.0, 1000.0), 500.0, 0.8, 200.0)),
            LoggedEdit(2, Crater((1500.0, 400.0), 450.0, 120.0)),
        ),
    )


def test_log_round_trips(hf, tmp_path):
    log = _log(hf)
    write_log(tmp_path / "e.jsonl", log)
    back = read_log(tmp_path / "e.jsonl")
    assert back == log
    assert check_log(back, hf) is back
    assert len((tmp_path / "e.jsonl").read_text().splitlines()) == 4


@pytest.mark.parametrize(
    "line, words",
    [
        ("{not json", "line 3: not JSON"),
        ('{"frame": 0, "brush": "melt", "centre": [1, 2], "radius": 1, "strength": 1}', "line 3: brush must be one of"),
        ('{"frame": 0, "brush": "raise", "centre": [1, 2], "radius": 1}', "line 3: a raise edit has keys"),
        ('{"frame": -1, "brush": "raise", "centre": [1, 2], "radius": 1, "strength": 1}', "line 3: frame"),
        ('{"frame": 0, "brush": "raise", "centre": [1], "radius": 1, "strength": 1}', "line 3: centre"),
        ('{"frame": 0, "brush": "raise", "centre": [1, 2], "radius": "big", "strength": 1}', "line 3: radius"),
        ("[1, 2]", "line 3: an edit must be a JSON object"),
    ],
)
def test_malformed_lines_are_refused_by_number(hf, tmp_path, line, words):
    lines = tmp_path / "ok.jsonl"
    write_log(lines, _log(hf))
    text = lines.read_text().splitlines()
    text.insert(2, line)
    bad = tmp_path / "bad.jsonl"
    bad.write_text("\n".join(text) + "\n")
    with pytest.raises(TerrabenchError, match=r"bad\.jsonl") as info:
        read_log(bad)
    assert words in str(info.value)


def test_frames_going_back_and_bad_headers_are_refused(hf, tmp_path):
    p = tmp_path / "e.jsonl"
    rec = {"frame": 3, "brush": "raise", "centre": [1, 2], "radius": 1, "strength": 1}
    write_log(p, _log(hf))
    p.write_text(p.read_text() + json.dumps(rec) + "\n" + json.dumps({**rec, "frame": 1}) + "\n")
    with pytest.raises(TerrabenchError, match="line 6: frame 1 comes after frame 3"):
        read_log(p)
    p.write_text(json.dumps(rec) + "\n")
    with pytest.raises(TerrabenchError, match="line 1: the first line must be the header"):
        read_log(p)
    p.write_text("")
    with pytest.raises(TerrabenchError, match="empty"):
        read_log(p)


def test_a_log_for_another_terrain_is_refused(hf, tmp_path):
    write_log(tmp_path / "e.jsonl", _log(hf))
    log = read_log(tmp_path / "e.jsonl")
    other = get_dataset("fbm", 65, seed=3)
    with pytest.raises(TerrabenchError, match="height digest"):
        check_log(log, other)
    with pytest.raises(TerrabenchError, match="samples"):
        check_log(log, get_dataset("fbm", 129))
    moved = HeightField(hf.heights, 31.0, name=hf.name)
    with pytest.raises(TerrabenchError, match="spacing"):
        check_log(log, moved)


def test_a_logged_brush_off_the_terrain_is_refused_by_edit_number(hf, tmp_path):
    log = EditLog(
        terrain_id(hf),
        (LoggedEdit(0, Raise((900.0, 700.0), 400.0, 50.0)), LoggedEdit(1, Raise((9000.0, 700.0), 400.0, 50.0))),
    )
    with pytest.raises(TerrabenchError, match="edit 2: raise brush centre"):
        check_log(log, hf)


def test_window_intersection_and_growth_clip_to_the_grid():
    w = Window(2, 5, 0, 4)
    assert w.intersection(Window(4, 9, 3, 9)) == Window(4, 5, 3, 4)
    assert w.intersection(Window(6, 9, 0, 4)).empty
    assert w.grown(1, 6, 4) == Window(1, 6, 0, 4)  # clipped at column 0, the last row and column
    assert Window(0, 1, 0, 1).grown(2, 10, 10) == Window(0, 3, 0, 3)
