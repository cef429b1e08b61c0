"""Flights: presets keep their promises, interpolation is smooth, files round-trip, bad files are named."""
import numpy as np
import pytest

from hybrid.camera.flight import PRESETS, Flight, preset
from hybrid.errors import TerrabenchError


def test_presets(puget257):
    for name in PRESETS:
        f = preset(name, puget257, frames=12, width=320, height=180)
        views = f.views()
        assert len(views) == 12
        for v in views:
            assert v.eye[2] > puget257.ground_height(*v.eye[:2]), name
    g = preset("grazing", puget257, frames=6)
    for v in g.views():
        assert abs(v.eye[2] - puget257.ground_height(*v.eye[:2]) - 2.0) < 1e-6
        assert abs(v.forward[2]) < 1e-9                       # looks at the horizon
    down = preset("lookdown", puget257, frames=3).view(1)
    assert down.forward[2] < -0.999


def test_interpolation_passes_keyframes_smoothly():
    eyes = np.array([[0, 0, 100], [100, 0, 100], [200, 50, 120], [300, 50, 100.0]])
    f = Flight("t", eyes, eyes + [0, 100, -50], frames=31)
    assert np.allclose(f.view(0).eye, eyes[0]) and np.allclose(f.view(30).eye, eyes[-1])
    assert np.allclose(f.view(10).eye, eyes[1])
    path = np.array([f.view(k).eye for k in range(31)])
    step = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert step.max() / step.min() < 3.0                      # no jumps


def test_save_load_roundtrip(tmp_path, puget257):
    f = preset("flyover", puget257, frames=9)
    for suffix in (".json", ".csv"):
        f.save(tmp_path / f"f{suffix}")
        g = Flight.load(tmp_path / f"f{suffix}")
        assert np.allclose(g.eyes, f.eyes) and np.allclose(g.targets, f.targets)
        assert (g.frames, g.width, g.fov_y, g.near) == (f.frames, f.width, f.fov_y, f.near)


def test_bad_flights(tmp_path, puget257):
    with pytest.raises(TerrabenchError, match="unknown flight"):
        preset("loop", puget257)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(TerrabenchError, match="malformed flight file"):
        Flight.load(tmp_path / "bad.json")
    with pytest.raises(TerrabenchError, match="frame must be"):
        preset("orbit", puget257, frames=4).view(4)
    with pytest.raises(TerrabenchError, match="frames must be"):
        Flight("x", [[0, 0, 1]], [[0, 1, 0]], frames=0)
