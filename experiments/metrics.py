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


# relative step of hit distance between 4-neighbours that marks a silhouette (a jump to a surface behind)
SILHOUETTE_STEP = 0.1


def _ratio(x: float, ref: float) -> float:
    """x / ref, with 0 / 0 = 1 (no change, as the reference) and x / 0 = inf."""
    return float(x / ref) if ref > 0 else (1.0 if x == 0 else float("inf"))


def near_silhouettes(distance: np.ndarray) -> np.ndarray:
    """Pixels (H x W bool) within one pixel (8-neighbourhood) of a silhouette: a 4-neighbour whose hit distance
    differs by more than SILHOUETTE_STEP relative to the nearer of the two, or that has no terrain."""
    d = np.where(np.isfinite(distance), distance.astype(np.float64), np.inf)
    edge = np.zeros(d.shape, dtype=bool)
    for a, b in ((d[:, :-1], d[:, 1:]), (d[:-1, :], d[1:, :])):
        with np.errstate(invalid="ignore"):
            step = ~(np.abs(b - a) <= SILHOUETTE_STEP * np.minimum(a, b))      # inf - inf counts as a step
        if a.shape[1] < d.shape[1]:
            edge[:, :-1] |= step
            edge[:, 1:] |= step
        else:
            edge[:-1, :] |= step
            edge[1:, :] |= step
    return grow(edge, 1)                          # silhouettes move by a pixel between methods


def grow(mask: np.ndarray, pixels: int) -> np.ndarray:
    """A boolean image with every set pixel grown into the (2 * pixels + 1)² square around it."""
    out = mask.copy()
    for _ in range(pixels):
        rows = out.copy()
        rows[1:] |= out[:-1]
        rows[:-1] |= out[1:]
        out = rows.copy()
        out[:, 1:] |= rows[:, :-1]
        out[:, :-1] |= rows[:, 1:]
    return out


def depth_jump_ratio(prev, cur, ref_prev, ref_cur) -> float:
    """Largest frame-to-frame change of hit distance of any pixel, against the reference's between the same views.

    Over the pixels P that all four frames cover (finite distance in the method's and the reference's frame,
    before and after) and that lie more than one pixel from a silhouette in any of the four
    (``near_silhouettes``), with d0, d1 the distances of a pixel in the two frames:

        depth_jump_ratio = max_P |d1 - d0| / d0 (method) / max_P |d1 - d0| / d0 (reference)

    1 = no pixel jumps further than the reference's own motion moves one; a level-of-detail switch that pops
    the surface shows as > 1. Silhouettes are left out because there a pixel moves from one surface to another
    and the hit distance jumps with the camera's motion alone, by a pixel's shift either way. NaN when no pixel
    qualifies.
    """
    frames = (prev, cur, ref_prev, ref_cur)
    for f in frames[1:]:
        _check_pair(prev, f)
    ok = np.ones(prev.distance.shape, dtype=bool)
    for f in frames:
        ok &= np.isfinite(f.distance) & ~near_silhouettes(f.distance)
    if not ok.any():
        return float("nan")
    def jump(a, b):
        d0, d1 = a.distance[ok].astype(np.float64), b.distance[ok].astype(np.float64)
        return float(np.max(np.abs(d1 - d0) / d0))
    return _ratio(jump(prev, cur), jump(ref_prev, ref_cur))


def temporal_errors(prev, cur, ref_prev, ref_cur) -> dict:
    """Popping: how much more the frame changes between consecutive frames than the reference does.

    change_ratio = mean |cur - prev| / mean |ref_cur - ref_prev| (1 = as stable as the reference);
    error_flicker = mean |(cur - ref_cur) - (prev - ref_prev)| in 8-bit units (0 = the error does not move);
    depth_jump_ratio = the largest relative change of hit distance of a pixel against the reference's
    (see ``depth_jump_ratio``).
    """
    a0, a1 = prev.colour.astype(np.float64), cur.colour.astype(np.float64)
    r0, r1 = ref_prev.colour.astype(np.float64), ref_cur.colour.astype(np.float64)
    ch, rch = np.abs(a1 - a0).mean(), np.abs(r1 - r0).mean()
    return {"change_ratio": _ratio(ch, rch), "error_flicker": float(np.abs((a1 - r1) - (a0 - r0)).mean()),
            "depth_jump_ratio": depth_jump_ratio(prev, cur, ref_prev, ref_cur)}


def hole_pixels_in_columns(frame) -> np.ndarray:
    """Cracks as an upright camera sees them: pixels without terrain that have terrain above in their column."""
    m = np.isfinite(frame.distance)
    above = np.maximum.accumulate(m, axis=0)
    return above & ~m


def frame_accuracy(frame, ref, flip: bool = True) -> dict:
    """All per-frame accuracy metrics in one dict."""
    return {**coverage_errors(frame, ref), **depth_errors(frame, ref), **image_errors(frame, ref, flip),
            "nan_px": int(np.count_nonzero(np.isnan(frame.distance)))}
