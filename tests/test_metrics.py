"""Accuracy metrics on constructed images: zero for identical frames, cracks apart from silhouette differences,
image errors over terrain only, known depth offsets recovered."""

import numpy as np

from experiments.metrics import (
    coverage_errors,
    crack_pixels,
    depth_errors,
    frame_accuracy,
    hole_pixels_in_columns,
    image_errors,
    near_silhouettes,
)
from hybrid.gl.target import RenderResult


def frame(h=40, w=60, dist=100.0, seed=0):
    rng = np.random.default_rng(seed)
    c = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    d = np.full((h, w), dist, np.float32)
    d[:10] = np.inf  # sky in the top rows
    return RenderResult(c, d)


def copy(f):
    return RenderResult(f.colour.copy(), f.distance.copy())


def mountains(h=60, w=90, shift_rows=0, shift_cols=0):
    """Terrain below a jagged outline (peaks and notches), optionally shifted down / right by whole pixels."""
    cols = np.arange(w) - shift_cols
    top = 20 + 8 * np.abs(np.sin(cols / 5.0)) + 4 * np.sin(cols / 1.7) + shift_rows
    d = np.where(np.arange(h)[:, None] >= top[None, :], 500.0, np.inf).astype(np.float32)
    return RenderResult(np.zeros((h, w, 3), np.uint8), d)


def test_identical_frames_have_zero_error():
    a = frame()
    m = frame_accuracy(a, a)
    assert m["hole_px"] == m["extra_px"] == m["crack_px"] == m["silhouette_px"] == 0
    assert m["coverage_mismatch"] == 0 and m["terrain_as_sky"] == 0
    assert m["depth_rel_max"] == 0 and m["psnr"] == float("inf") and np.isclose(m["ssim"], 1.0)
    assert m["flip"] == 0.0


def test_hole_inside_terrain_is_a_crack_and_a_floating_pixel_a_silhouette_difference():
    ref = frame()
    f = copy(ref)
    f.distance[20:23, 5:9] = np.inf  # 12-pixel hole, terrain all around it
    f.distance[2, 2] = 50.0  # 1 extra pixel in the sky
    c = coverage_errors(f, ref)
    assert c["hole_px"] == 12 and c["extra_px"] == 1
    assert c["crack_px"] == 12 and c["silhouette_px"] == 1
    assert np.isclose(c["terrain_as_sky"], 12 / (30 * 60))
    assert hole_pixels_in_columns(ref).sum() == 0
    # the floating extra pixel makes the 7 sky pixels below it in column 2 count as holes in their column
    assert hole_pixels_in_columns(f).sum() == 12 + 7


def test_one_pixel_crack_counts_and_a_crack_reaching_the_outline_counts_below_it():
    ref = frame()
    f = copy(ref)
    f.distance[25, 30] = np.inf  # a one-pixel crack deep inside terrain
    c = coverage_errors(f, ref)
    assert c["crack_px"] == 1 and c["silhouette_px"] == 0
    g = copy(ref)
    g.distance[10:18, 40] = np.inf  # a one-pixel-wide crack open to the sky above
    cracks = crack_pixels(g, ref)
    assert cracks[12:18, 40].all() and cracks.sum() == 6  # all but the two pixels next to the reference's sky


def test_shifted_silhouette_is_no_crack():
    ref = mountains()
    for dr, dc in ((1, 0), (0, 1), (1, 2), (-1, -1), (2, -2)):
        moved = mountains(shift_rows=dr, shift_cols=dc)
        c = coverage_errors(moved, ref)
        assert c["hole_px"] + c["extra_px"] > 20, (dr, dc)
        assert c["crack_px"] == 0, (dr, dc)
        assert c["silhouette_px"] == c["hole_px"] + c["extra_px"]


def test_identical_sky_does_not_inflate_image_metrics():
    ref = frame()
    f = copy(ref)
    rng = np.random.default_rng(5)
    f.colour[10:] = np.clip(f.colour[10:].astype(int) + rng.integers(-20, 21, f.colour[10:].shape), 0, 255)
    small = image_errors(f, ref)
    # the same terrain under 60 more rows of sky that both images draw identically
    sky = np.full((60, 60, 3), 200, np.uint8)
    tall_ref = RenderResult(
        np.concatenate([sky, ref.colour]), np.concatenate([np.full((60, 60), np.inf), ref.distance])
    )
    tall = RenderResult(np.concatenate([sky, f.colour]), np.concatenate([np.full((60, 60), np.inf), f.distance]))
    big = image_errors(tall, tall_ref)
    assert np.isclose(big["psnr"], small["psnr"], rtol=1e-9)
    assert abs(big["ssim"] - small["ssim"]) < 0.002 and small["ssim"] < 0.995
    assert np.isclose(big["flip"], small["flip"], rtol=0.05) and small["flip"] > 0.01
    # neither image shows terrain: nothing to compare
    empty = RenderResult(sky, np.full((60, 60), np.inf))
    assert all(np.isnan(v) for v in image_errors(empty, empty).values())


def test_known_depth_offset():
    ref = frame()
    f = RenderResult(ref.colour, np.where(np.isfinite(ref.distance), ref.distance * 1.01, np.inf).astype(np.float32))
    d = depth_errors(f, ref)
    assert np.isclose(d["depth_rel_median"], 0.01, rtol=1e-5) and np.isclose(d["depth_rel_max"], 0.01, rtol=1e-5)


def test_image_error_grows_with_noise():
    ref = frame()
    small = RenderResult(np.clip(ref.colour.astype(int) + 2, 0, 255).astype(np.uint8), ref.distance)
    big = RenderResult(np.clip(ref.colour.astype(int) + 40, 0, 255).astype(np.uint8), ref.distance)
    a, b = frame_accuracy(small, ref), frame_accuracy(big, ref)
    assert a["psnr"] > b["psnr"] and a["ssim"] > b["ssim"] and a["flip"] < b["flip"]


def _ramp(h=48, w=64, ridge_rows=None):
    """A smooth ground seen from above the horizon: distance grows upwards, sky on the top rows, optionally
    a nearer ridge (200 m) over the given rows."""
    rows = np.arange(h, dtype=np.float64)[:, None] * np.ones((1, w))
    d = 2000.0 - 20.0 * rows + 0.5 * np.arange(w)[None, :]
    d[:6] = np.inf
    if ridge_rows is not None:
        d[ridge_rows] = 200.0
    return RenderResult(np.zeros((h, w, 3), np.uint8), d.astype(np.float32))


def test_near_silhouettes_marks_depth_steps_and_sky_borders():
    f = _ramp(ridge_rows=slice(20, 26))
    m = near_silhouettes(f.distance)
    assert m[4:8].all() and not m[9:18].any()  # the horizon (sky above row 6), two pixels each side
    assert m[18:22].all() and m[24:28].all() and not m[22:24].any() and not m[29:].any()
