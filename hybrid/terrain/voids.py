"""Void (no-data) filling of height grids: biharmonic inpainting per void, bounded by the void's rim.

Method: scikit-image's ``inpaint_biharmonic`` (Damelin and Hoang 2018), run region by region: each
connected void is solved as a sparse linear system over its bounding box grown by the stencil's radius,
so the cost follows the voids, not the grid. The biharmonic fill continues the surrounding slope and
curvature smoothly across the void (no rings or grooves), but as a fourth-order fill it may overshoot;
each void's fill is therefore bounded by the lowest and highest known samples on its rim (the known
8-neighbours of its samples), and the number of samples that bound moved is reported, never hidden.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.errors import TerrabenchError

METHOD = "biharmonic inpainting (scikit-image inpaint_biharmonic, per void)"
EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True)
class VoidFill:
    """What a void fill did: samples filled, voids (8-connected), the largest void, samples the rim bounded."""

    samples: int
    voids: int
    largest: int
    bounded: int  # samples held at or moved to their void's rim range
    method: str = METHOD

    def describe(self, total: int) -> str:
        """One sentence for warnings and notes; total is the grid's sample count."""
        return (
            f"{self.samples} no-data samples ({100 * self.samples / total:.2f} %) in {self.voids} "
            f"void{'s' if self.voids != 1 else ''} "
            f"(largest {self.largest} samples) filled by {self.method}, each void bounded by its rim's height "
            f"range ({self.bounded} samples held to that range)"
        )


def rim_ranges(
    values: np.ndarray, missing: np.ndarray, labels: np.ndarray, count: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per void label 1..count: min and max of the known samples 8-adjacent to it (index 0 unused)."""
    lo = np.full(count + 1, np.inf)
    hi = np.full(count + 1, -np.inf)
    rows, cols = values.shape
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == 0 and dj == 0:
                continue
            # p: samples of the grid that have a neighbour q = p + (di, dj) inside it
            p = (slice(max(-di, 0), rows - max(di, 0)), slice(max(-dj, 0), cols - max(dj, 0)))
            q = (slice(max(di, 0), rows + min(di, 0)), slice(max(dj, 0), cols + min(dj, 0)))
            pair = missing[p] & ~missing[q]
            lab, val = labels[p][pair], values[q][pair]
            np.minimum.at(lo, lab, val)
            np.maximum.at(hi, lab, val)
    return lo, hi


def fill_voids(values: np.ndarray, missing: np.ndarray, integer: bool = False) -> tuple[np.ndarray, VoidFill]:
    """Heights (float64, same units) with samples where ``missing`` is True filled; and what was done. With
    ``integer`` (a source of integer codes) the fill is rounded to integers, so the grid stays on the source's
    step and its 16-bit tiles stay exact (the rim's range, of integers, still bounds it)."""
    from scipy import ndimage
    from skimage.restoration import inpaint_biharmonic

    missing = np.asarray(missing, dtype=bool)
    if not missing.any():
        return np.asarray(values, dtype=np.float64), VoidFill(0, 0, 0, 0)
    if missing.all():
        raise TerrabenchError("every sample is no-data: nothing to fill from")
    known = np.where(missing, 0.0, np.asarray(values, dtype=np.float64))
    labels, count = ndimage.label(missing, structure=EIGHT)
    sizes = np.bincount(labels.ravel())[1:]
    filled = inpaint_biharmonic(known, missing, split_into_regions=True)
    lo, hi = rim_ranges(known, missing, labels, count)
    fill, low, high = filled[missing], lo[labels[missing]], hi[labels[missing]]
    # held by the rim's range: fills beyond it, or at its extreme where scikit-image's own clip to the grid's
    # known range put them (a summit inside a void); on a flat rim, only fills that differ from its height
    off_flat = np.abs(fill - high) > 1e-9 * np.maximum(1.0, np.abs(high))
    held = np.where(high > low, (fill >= high) | (fill <= low), off_flat)
    fill = np.clip(fill, low, high)
    filled[missing] = np.rint(fill) if integer else fill
    method = METHOD + (", rounded to the source's integer step" if integer else "")
    return filled, VoidFill(int(missing.sum()), int(count), int(sizes.max()), int(np.count_nonzero(held)), method)
