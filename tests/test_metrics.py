"""Accuracy metrics on constructed images: zero for identical frames, known holes and offsets recovered."""
import numpy as np

from experiments.metrics import (coverage_errors, depth_errors, depth_jump_ratio, frame_accuracy,
                                 hole_pixels_in_columns, near_silhouettes, temporal_errors)
from hybrid.gl.target import RenderResult


def frame(h=40, w=60, dist=100.0, seed=0):
    rng = np.random.default_rng(seed)
    c = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    d = np.full((h, w), dist, np.float32)
    d[:10] = np.inf                                          # sky in the top rows
    return RenderResult(c, d)


def test_identical_frames_have_zero_error():
    a = frame()
    m = frame_accuracy(a, a)
    assert m["hole_px"] == m["extra_px"] == 0 and m["coverage_mismatch"] == 0
    assert m["depth_rel_max"] == 0 and m["psnr"] == float("inf") and np.isclose(m["ssim"], 1.0)
    assert m["flip"] == 0.0


def test_known_hole_and_extra():
    ref = frame()
    f = RenderResult(ref.colour.copy(), ref.distance.copy())
    f.distance[20:23, 5:9] = np.inf                          # 12-pixel hole
    f.distance[2, 2] = 50.0                                  # 1 extra pixel
    c = coverage_errors(f, ref)
    assert c["hole_px"] == 12 and c["extra_px"] == 1
    assert hole_pixels_in_columns(ref).sum() == 0
    # the floating extra pixel makes the 7 sky pixels below it in column 2 count as cracks too
    assert hole_pixels_in_columns(f).sum() == 12 + 7


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


def test_temporal_popping():
    r0, r1 = frame(seed=1), frame(seed=1)
    stable = temporal_errors(r0, r1, r0, r1)
    assert stable["error_flicker"] == 0 and stable["change_ratio"] == 1.0
    pop = RenderResult(r1.colour.copy(), r1.distance)
    pop.colour[20:30, 20:30] = 255 - pop.colour[20:30, 20:30]
    r1b = frame(seed=1)
    r1b.colour[0, 0] = 0 if r1b.colour[0, 0, 0] else 1      # tiny reference motion
    t = temporal_errors(r0, pop, r0, r1b)
    assert t["error_flicker"] > 1.0 and t["change_ratio"] > 10


def _ramp(h=48, w=64, scale=1.0, ridge_rows=None):
    """A smooth ground seen from above the horizon: distance grows upwards, sky on the top rows, optionally
    a nearer ridge (200 m) over the given rows; distances times ``scale`` (the camera's motion)."""
    rows = np.arange(h, dtype=np.float64)[:, None] * np.ones((1, w))
    d = (2000.0 - 20.0 * rows + 0.5 * np.arange(w)[None, :]) * scale
    d[:6] = np.inf
    if ridge_rows is not None:
        d[ridge_rows] = 200.0 * scale
    return RenderResult(np.zeros((h, w, 3), np.uint8), d.astype(np.float32))


def test_depth_jump_ratio_finds_a_put_in_jump():
    ridge = slice(20, 26)
    ref0, ref1 = _ramp(ridge_rows=ridge), _ramp(scale=1.002, ridge_rows=ridge)      # the reference moves 0.2 %
    # the same motion as the reference: ratio 1, also in temporal_errors
    assert np.isclose(depth_jump_ratio(ref0, ref1, ref0, ref1), 1.0)
    assert np.isclose(temporal_errors(ref0, ref1, ref0, ref1)["depth_jump_ratio"], 1.0)
    # a 5 x 5 patch away from silhouettes pops by 1 % more: the ratio is (1.002 * 1.01 - 1) / 0.002
    pop = _ramp(scale=1.002, ridge_rows=ridge)
    pop.distance[34:39, 30:35] *= np.float32(1.01)
    assert np.isclose(depth_jump_ratio(ref0, pop, ref0, ref1), (1.002 * 1.01 - 1) / 0.002, rtol=1e-3)   # float32
    # the method's ridge one pixel lower in the second frame: pixels there jump from the ridge to the ground
    # behind it and back (a silhouette, not popping) and are left out
    moved = _ramp(scale=1.002, ridge_rows=slice(21, 27))
    assert np.isclose(depth_jump_ratio(ref0, moved, ref0, ref1), 1.0, rtol=1e-3)
    # without motion in the reference a change of the method is infinitely worse; none at all is 1
    assert depth_jump_ratio(ref0, ref1, ref0, ref0) == float("inf")
    assert depth_jump_ratio(ref0, ref0, ref0, ref0) == 1.0


def test_near_silhouettes_marks_depth_steps_and_sky_borders():
    f = _ramp(ridge_rows=slice(20, 26))
    m = near_silhouettes(f.distance)
    assert m[4:8].all() and not m[9:18].any()               # the horizon (sky above row 6), two pixels each side
    assert m[18:22].all() and m[24:28].all() and not m[22:24].any() and not m[29:].any()
