"""Accuracy of a frame against the reference frame: coverage, depth, image error, temporal stability.

Inputs are RenderResult-like objects (``colour`` H x W x 3 uint8, ``distance`` H x W metres with inf where
there is no terrain). Pixels are compared one to one (same view, same size).
"""
from __future__ import annotations

import os

import numpy as np

# FLIP's worker threads otherwise spin after each evaluation and slow the next timed frame
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from hybrid.errors import TerrabenchError


def _check_pair(a, b):
    if a.colour.shape != b.colour.shape or a.distance.shape != b.distance.shape:
        raise TerrabenchError(f"frames differ in size: {a.colour.shape} vs {b.colour.shape}")


def coverage_errors(frame, ref) -> dict:
    """Holes (reference has terrain, frame not) and extra pixels (frame has, reference not), counts and %."""
    _check_pair(frame, ref)
    m, r = np.isfinite(frame.distance), np.isfinite(ref.distance)
    holes, extra = int(np.count_nonzero(r & ~m)), int(np.count_nonzero(m & ~r))
    total = m.size
    return {"hole_px": holes, "extra_px": extra, "coverage_mismatch": (holes + extra) / total,
            "coverage": float(m.mean()), "ref_coverage": float(r.mean())}


def depth_errors(frame, ref) -> dict:
    """Relative hit-distance error |d - d_ref| / d_ref over pixels both cover: median, p99, max."""
    _check_pair(frame, ref)
    both = np.isfinite(frame.distance) & np.isfinite(ref.distance)
    if not both.any():
        return {"depth_rel_median": np.nan, "depth_rel_p99": np.nan, "depth_rel_max": np.nan}
    d = frame.distance[both].astype(np.float64)
    r = ref.distance[both].astype(np.float64)
    rel = np.abs(d - r) / r
    return {"depth_rel_median": float(np.median(rel)), "depth_rel_p99": float(np.percentile(rel, 99)),
            "depth_rel_max": float(rel.max())}


def image_errors(frame, ref, flip: bool = True) -> dict:
    """PSNR (dB) and SSIM (scikit-image) and mean FLIP (flip-evaluator) of the colour images."""
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity
    _check_pair(frame, ref)
    a, b = frame.colour, ref.colour
    if np.array_equal(a, b):
        psnr = float("inf")
    else:
        psnr = float(peak_signal_noise_ratio(b, a, data_range=255))
    win = min(7, min(a.shape[:2]) // 2 * 2 - 1)
    ssim = float(structural_similarity(b, a, channel_axis=2, data_range=255, win_size=max(win, 3)))
    out = {"psnr": psnr, "ssim": ssim}
    if flip:
        import flip_evaluator
        _, mean, _ = flip_evaluator.evaluate(b.astype(np.float32) / 255.0, a.astype(np.float32) / 255.0, "LDR",
                                             applyMagma=False)
        out["flip"] = float(mean)
    return out


def temporal_errors(prev, cur, ref_prev, ref_cur) -> dict:
    """Popping: how much more the frame changes between consecutive frames than the reference does.

    change_ratio = mean |cur - prev| / mean |ref_cur - ref_prev| (1 = as stable as the reference);
    error_flicker = mean |(cur - ref_cur) - (prev - ref_prev)| in 8-bit units (0 = the error does not move).
    """
    a0, a1 = prev.colour.astype(np.float64), cur.colour.astype(np.float64)
    r0, r1 = ref_prev.colour.astype(np.float64), ref_cur.colour.astype(np.float64)
    ch, rch = np.abs(a1 - a0).mean(), np.abs(r1 - r0).mean()
    return {"change_ratio": float(ch / rch) if rch > 0 else (1.0 if ch == 0 else float("inf")),
            "error_flicker": float(np.abs((a1 - r1) - (a0 - r0)).mean())}


def hole_pixels_in_columns(frame) -> np.ndarray:
    """Cracks as an upright camera sees them: pixels without terrain that have terrain above in their column."""
    m = np.isfinite(frame.distance)
    above = np.maximum.accumulate(m, axis=0)
    return above & ~m


def frame_accuracy(frame, ref, flip: bool = True) -> dict:
    """All per-frame accuracy metrics in one dict."""
    return {**coverage_errors(frame, ref), **depth_errors(frame, ref), **image_errors(frame, ref, flip),
            "nan_px": int(np.count_nonzero(np.isnan(frame.distance)))}
