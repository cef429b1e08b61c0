"""Accuracy metrics on constructed images: zero for identical frames, known holes and offsets recovered."""
import numpy as np

from experiments.metrics import coverage_errors, depth_errors, frame_accuracy, hole_pixels_in_columns, temporal_errors
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
