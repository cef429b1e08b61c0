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
        assert v.eye[2] - puget257.ground_height(*v.eye[:2]) >= 2.0
        assert abs(v.forward[2]) < 1e-9  # a level view
    down = preset("lookdown", puget257, frames=3).view(1)
    assert down.forward[2] < -0.999


def test_interpolation_passes_keyframes_smoothly():
    eyes = np.array([[0, 0, 100], [100, 0, 100], [200, 50, 120], [300, 50, 100.0]])
    f = Flight("t", eyes, eyes + [0, 100, -50], frames=31)
    assert np.allclose(f.view(0).eye, eyes[0]) and np.allclose(f.view(30).eye, eyes[-1])
    assert np.allclose(f.view(10).eye, eyes[1])
    path = np.array([f.view(k).eye for k in range(31)])
    step = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert step.max() / step.min() < 3.0  # no jumps


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


def _ground_along_ray(hf, eye, direction, far):
    """Distance (m) along a ray to the first point below the ground, marched in 1 m steps; inf if none."""
    t = np.arange(1.0, far, 1.0)
    p = eye + t[:, None] * direction
    below = p[:, 2] <= hf.ground_height(p[:, 0], p[:, 1])
    return float(t[np.argmax(below)]) if below.any() else np.inf


def test_dolly_moves_slowly_and_steadily_above_the_terrain(puget257):
    hf = puget257
    f = preset("dolly", hf, frames=24)
    views = f.views()
    eyes = np.array([v.eye for v in views])
    assert len(views) == 24
    clearance = eyes[:, 2] - hf.ground_height(eyes[:, 0], eyes[:, 1])
    # above the ground under the eye by the margin (30 m or a fifth of the local relief), at every frame
    assert clearance.min() >= 30.0
    step = np.linalg.norm(np.diff(eyes, axis=0), axis=1)
    assert np.allclose(step, step[0], rtol=1e-6) and 0.1 <= step[0] <= 2.0  # at most a few metres, steadily
    assert np.allclose(np.diff(eyes[:, 2]), 0.0)  # level
    for v in views[::6]:
        assert -0.2 < v.forward[2] < -0.05  # ahead and slightly down
        hit = _ground_along_ray(hf, v.eye, v.forward, 60000.0)
        assert np.isfinite(hit) and step[0] / hit < 0.01  # motion small against the distance in view
    assert step[0] / clearance.min() < 0.2
    again = preset("dolly", hf, frames=24).views()
    assert all(np.array_equal(a.eye, b.eye) and np.array_equal(a.target, b.target) for a, b in zip(views, again))


def _local_relief(hf, x, y, cells):
    """Highest minus lowest height sample within ``cells`` cells (a square window) of the sample nearest (x, y)."""
    i = int(round((y - hf.origin[1]) / hf.spacing_y))
    j = int(round((x - hf.origin[0]) / hf.spacing_x))
    w = hf.heights[max(i - cells, 0) : i + cells + 1, max(j - cells, 0) : j + cells + 1]
    return float(w.max() - w.min()) if w.size else 0.0


STEEP = ("cliff", "ridged", "spike")


@pytest.mark.parametrize("terrain", STEEP + ("puget257", "puget_full"))
def test_every_eye_clears_the_ground_by_a_margin_of_the_local_relief(request, synthetic, terrain):
    hf = request.getfixturevalue(terrain) if terrain.startswith("puget") else synthetic(terrain)
    for name in PRESETS:
        for v in preset(name, hf, frames=12, width=160, height=90).views():
            x, y, z = v.eye
            clearance = z - float(hf.ground_height(x, y))
            assert clearance >= max(2.0, 0.1 * _local_relief(hf, x, y, 4)), (terrain, name, clearance)


@pytest.mark.parametrize("terrain", STEEP + ("fbm", "puget257", "puget_full"))
def test_grazing_sees_sky_above_and_terrain_below(ctx, request, synthetic, terrain):
    from hybrid.reference import ReferenceRenderer

    hf = request.getfixturevalue(terrain) if terrain.startswith("puget") else synthetic(terrain)
    with ReferenceRenderer(ctx, hf) as ref:
        for k, v in enumerate(preset("grazing", hf, frames=6, width=160, height=90).views()):
            terrain_px = ref.render(v, mode="shaded").mask
            q = v.height // 4
            sky_top, ground_bottom = 1.0 - terrain_px[:q].mean(), terrain_px[-q:].mean()
            assert sky_top >= 0.5 and ground_bottom >= 0.9, (terrain, k, sky_top, ground_bottom)
