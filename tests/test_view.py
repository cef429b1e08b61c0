"""Projections against hand-computed cases, depth/distance round trips, and view validation."""

import numpy as np
import pytest

from hybrid.camera.view import View
from hybrid.errors import TerrabenchError


def make():
    # eye at origin looking north, fov 90 degrees, 200x100 viewport, near 1, far 1000
    return View([0, 0, 0], [0, 10, 0], 90.0, 200, 100, 1.0, 1000.0)


def test_hand_computed_projection():
    v = make()
    p = v.project(np.array([[0, 10, 0], [10, 10, 0], [0, 10, 5], [0, 1, 0], [0, 1000, 0]], float))
    assert np.allclose(p[0], [100, 50, 990 / (10 * 999)])  # centre; reversed-Z depth n(f-z)/(z(f-n))
    assert np.allclose(p[1, :2], [150, 50])  # 45 deg right at aspect 2 -> ndc x = 0.5
    assert np.allclose(p[2, :2], [100, 25])  # tan = 0.5 up -> ndc y = 0.5 -> row 25
    assert np.isclose(p[3, 2], 1.0) and np.isclose(p[4, 2], 0.0)  # near -> 1, far -> 0


def test_distance_from_depth_roundtrip():
    v = View([3, -4, 100], [500, 800, -20], 50.0, 64, 48, 0.5, 1e6)
    rows, cols = np.mgrid[0:48, 0:64]
    d = np.array([10.0, 1000.0, 1e5])
    for dist in d:
        pts = v.eye + v.pixel_rays(rows, cols) * dist
        depth = v.project(pts)[..., 2]
        got = v.distance_from_depth(depth.astype(np.float32))
        assert np.allclose(got, dist, rtol=2e-6)
    assert np.all(np.isinf(v.distance_from_depth(np.zeros((48, 64), np.float32))))


def test_frustum_planes_inside_outside():
    v = make()
    planes = v.frustum_planes_rel()
    inside = np.array([0, 10, 0.0]) - v.eye
    assert np.all(planes[:, :3] @ inside + planes[:, 3] > 0)
    for out in ([0, -10, 0], [30, 10, 0], [0, 10, 30], [0, 0.5, 0], [0, 2000, 0]):
        q = np.array(out, float) - v.eye
        assert np.any(planes[:, :3] @ q + planes[:, 3] < 0), out


def test_straight_down_view_is_defined():
    v = View([0, 0, 100], [0, 0, 0], 60, 32, 32, 1, 1000)
    assert np.allclose(v.project(np.array([[0, 0, 0.0]]))[0, :2], [16, 16])
    assert np.all(np.isfinite(v.view_proj_rel))


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(fov_y=0), "fov_y"),
        (dict(fov_y=180), "fov_y"),
        (dict(width=0), "width"),
        (dict(height=100000), "height"),
        (dict(near=0), "near"),
        (dict(near=10, far=5), "far"),
        (dict(target=[0, 0, 0]), "target must differ"),
        (dict(eye=[0, np.nan, 0]), "eye"),
        (dict(near=6.6e-247, far=1.0), "far / near is 1.52e\\+246"),
    ],
)
def test_bad_views(kw, match):
    args = dict(eye=[0, 0, 0], target=[0, 10, 0], fov_y=60, width=10, height=10, near=1, far=100)
    args.update(kw)
    with pytest.raises(TerrabenchError, match=match):
        View(**args)


def test_depth_to_distance_in_bounded_memory_and_exact():
    import tracemalloc

    v = View(eye=(0.0, 0.0, 500.0), target=(1000.0, 700.0, 0.0), width=4096, height=4096)
    depth = np.full((4096, 4096), 0.5, np.float32)
    depth[:10] = 0.0  # sky
    tracemalloc.start()
    dist = v.distance_from_depth(depth)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert dist.dtype == np.float32 and np.isinf(dist[:10]).all() and np.isfinite(dist[10:]).all()
    assert peak < 64 * 2**20 + 200 * 2**20  # the float32 result plus bounded chunks, not (H, W, 3) float64
    rows, cols = np.array([10, 2000, 4095]), np.array([0, 3000, 4095])
    ray = v.pixel_dirs_eye(rows, cols)  # eye-space ray (x, y, -1): length scales z-distance
    n, f = v.near, v.far
    zdist = n * f / (f - n) / (n / (f - n) + 0.5)
    np.testing.assert_allclose(dist[rows, cols], zdist * np.linalg.norm(ray, axis=-1), rtol=1e-6)
