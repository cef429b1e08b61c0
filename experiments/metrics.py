"""Accuracy of a frame against the reference frame: coverage (cracks apart from silhouettes), depth, image.

Inputs are RenderResult-like objects (``colour`` H x W x 3 uint8, ``distance`` H x W metres with inf where
there is no terrain). Pixels are compared one to one (same view, same size).

Coverage splits the pixels where frame and reference disagree on terrain into
- cracks: the frame shows sky where the reference has terrain, the frame's own terrain encloses the pixel
  (terrain within CRACK_WINDOW pixels on both sides, left and right or above and below), and the pixel lies
  more than OUTLINE_PX pixels from the reference's sky (``crack_pixels``);
- silhouette differences: every other disagreeing pixel, i.e. the outline drawn a little elsewhere.
Image metrics (PSNR, SSIM, FLIP) are taken over the terrain pixels of either image (the union): sky that both
draw identically neither dilutes nor inflates them. Depth errors are over the pixels both cover.
Temporal measures (popping) are in ``experiments.popping``.
"""

from __future__ import annotations

import os

import numpy as np

# FLIP's worker threads otherwise spin after each evaluation and slow the next timed frame
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from hybrid.errors import TerrabenchError

# pixels each side within which the frame's own terrain must enclose a sky pixel for it to count as a crack
CRACK_WINDOW = 3
# pixels from the reference's sky within which a missing pixel counts as the outline drawn elsewhere (a level of
# detail of tau <= 2 px may move the outline that far; the notches of a shifted jagged outline look enclosed)
OUTLINE_PX = 2
# relative step of hit distance between 4-neighbours that marks a silhouette (a jump to a surface behind)
SILHOUETTE_STEP = 0.1


def check_pair(a, b) -> None:
    """Refuse two frames of different sizes."""
    if a.colour.shape != b.colour.shape or a.distance.shape != b.distance.shape:
        raise TerrabenchError(f"frames differ in size: {a.colour.shape} vs {b.colour.shape}")


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


def _any_within(mask: np.ndarray, window: int, axis: int, before: bool) -> np.ndarray:
    """Per pixel: whether mask is set in any of the `window` pixels before (or after) it along axis."""
    m = np.moveaxis(mask, axis, -1).astype(np.int32)
    n = m.shape[-1]
    c = np.concatenate([np.zeros(m.shape[:-1] + (1,), np.int32), np.cumsum(m, axis=-1)], axis=-1)
    idx = np.arange(n)
    if before:  # pixels idx - window .. idx - 1
        lo, hi = np.maximum(idx - window, 0), idx
    else:  # pixels idx + 1 .. idx + window
        lo, hi = np.minimum(idx + 1, n), np.minimum(idx + 1 + window, n)
    return np.moveaxis(c[..., hi] - c[..., lo] > 0, -1, axis)


def enclosed_sky(terrain: np.ndarray, window: int = CRACK_WINDOW) -> np.ndarray:
    """Sky pixels (H x W bool) with terrain within `window` pixels on both sides, horizontally or vertically."""
    horizontal = _any_within(terrain, window, 1, True) & _any_within(terrain, window, 1, False)
    vertical = _any_within(terrain, window, 0, True) & _any_within(terrain, window, 0, False)
    return ~terrain & (horizontal | vertical)


def crack_pixels(frame, ref, window: int = CRACK_WINDOW) -> np.ndarray:
    """Cracks (H x W bool): sky in the frame, terrain in the reference, enclosed by the frame's own terrain
    (``enclosed_sky``) and more than OUTLINE_PX pixels from the reference's sky (off its outline)."""
    check_pair(frame, ref)
    r = np.isfinite(ref.distance)
    return enclosed_sky(np.isfinite(frame.distance), window) & r & ~grow(~r, OUTLINE_PX)


def coverage_errors(frame, ref) -> dict:
    """Coverage against the reference, in pixels and fractions.

    hole_px: reference terrain drawn as sky, of which crack_px are cracks (``crack_pixels``);
    extra_px: terrain where the reference has sky; silhouette_px = hole_px - crack_px + extra_px;
    terrain_as_sky = hole_px / the reference's terrain pixels; coverage_mismatch = (hole + extra) / all pixels.
    """
    check_pair(frame, ref)
    m, r = np.isfinite(frame.distance), np.isfinite(ref.distance)
    holes, extra = int(np.count_nonzero(r & ~m)), int(np.count_nonzero(m & ~r))
    cracks = int(np.count_nonzero(crack_pixels(frame, ref)))
    ref_px = int(np.count_nonzero(r))
    return {
        "hole_px": holes,
        "extra_px": extra,
        "crack_px": cracks,
        "silhouette_px": holes - cracks + extra,
        "terrain_as_sky": holes / ref_px if ref_px else np.nan,
        "coverage_mismatch": (holes + extra) / m.size,
        "coverage": float(m.mean()),
        "ref_coverage": float(r.mean()),
    }


def depth_errors(frame, ref) -> dict:
    """Relative hit-distance error |d - d_ref| / d_ref over pixels both cover: median, p99, max."""
    check_pair(frame, ref)
    both = np.isfinite(frame.distance) & np.isfinite(ref.distance)
    if not both.any():
        return {"depth_rel_median": np.nan, "depth_rel_p99": np.nan, "depth_rel_max": np.nan}
    d = frame.distance[both].astype(np.float64)
    r = ref.distance[both].astype(np.float64)
    rel = np.abs(d - r) / r
    return {
        "depth_rel_median": float(np.median(rel)),
        "depth_rel_p99": float(np.percentile(rel, 99)),
        "depth_rel_max": float(rel.max()),
    }


def image_errors(frame, ref, flip: bool = True) -> dict:
    """PSNR (dB), SSIM (scikit-image) and mean FLIP (flip-evaluator) of the colour images over the pixels where
    either image shows terrain; NaN when neither does. SSIM and FLIP maps are computed on the whole image (their
    windows see the sky next to the terrain) and averaged over those pixels."""
    from skimage.metrics import structural_similarity

    check_pair(frame, ref)
    a, b = frame.colour, ref.colour
    terrain = np.isfinite(frame.distance) | np.isfinite(ref.distance)
    if not terrain.any():
        return {"psnr": np.nan, "ssim": np.nan, **({"flip": np.nan} if flip else {})}
    mse = float(np.mean((a[terrain].astype(np.float64) - b[terrain].astype(np.float64)) ** 2))
    psnr = float("inf") if mse == 0 else float(10 * np.log10(255.0**2 / mse))
    win = min(7, min(a.shape[:2]) // 2 * 2 - 1)
    _, smap = structural_similarity(b, a, channel_axis=2, data_range=255, win_size=max(win, 3), full=True)
    out = {"psnr": psnr, "ssim": float(smap.mean(axis=2)[terrain].mean())}
    if flip:
        import flip_evaluator

        fmap, _, _ = flip_evaluator.evaluate(
            b.astype(np.float32) / 255.0, a.astype(np.float32) / 255.0, "LDR", applyMagma=False
        )
        out["flip"] = float(np.asarray(fmap).reshape(terrain.shape)[terrain].mean())
    return out


def near_silhouettes(distance: np.ndarray) -> np.ndarray:
    """Pixels (H x W bool) within one pixel (8-neighbourhood) of a silhouette: a 4-neighbour whose hit distance
    differs by more than SILHOUETTE_STEP relative to the nearer of the two, or that has no terrain."""
    d = np.where(np.isfinite(distance), distance.astype(np.float64), np.inf)
    edge = np.zeros(d.shape, dtype=bool)
    for a, b in ((d[:, :-1], d[:, 1:]), (d[:-1, :], d[1:, :])):
        with np.errstate(invalid="ignore"):
            step = ~(np.abs(b - a) <= SILHOUETTE_STEP * np.minimum(a, b))  # inf - inf counts as a step
        if a.shape[1] < d.shape[1]:
            edge[:, :-1] |= step
            edge[:, 1:] |= step
        else:
            edge[:-1, :] |= step
            edge[1:, :] |= step
    return grow(edge, 1)  # silhouettes move by a pixel between methods


def hole_pixels_in_columns(frame) -> np.ndarray:
    """Cracks as an upright camera sees them: pixels without terrain that have terrain above in their column."""
    m = np.isfinite(frame.distance)
    above = np.maximum.accumulate(m, axis=0)
    return above & ~m


def frame_accuracy(frame, ref, flip: bool = True) -> dict:
    """All per-frame accuracy metrics in one dict."""
    return {
        **coverage_errors(frame, ref),
        **depth_errors(frame, ref),
        **image_errors(frame, ref, flip),
        "nan_px": int(np.count_nonzero(np.isnan(frame.distance))),
    }
