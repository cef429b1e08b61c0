"""CPU mirror of the vertex shader's tilelet frustum test (for counters and tests)."""
from __future__ import annotations

import numpy as np

from .quadtree import Leaves, leaf_heights


def tilelet_boxes(heights: np.ndarray, leaves: Leaves, origin_rel, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Eye-relative (min, max) corners (count, 3) of each tilelet's box: footprint x post height range, metres."""
    o = np.asarray(origin_rel, dtype=np.float64)
    P = leaf_heights(heights, leaves).reshape(len(leaves), 9).astype(np.float64)
    k2 = (2 << leaves.level).astype(np.float64)
    lo = np.stack([o[0] + leaves.j0 * spacing, o[1] + leaves.i0 * spacing, o[2] + P.min(axis=1)], axis=1)
    hi = np.stack([o[0] + (leaves.j0 + k2) * spacing, o[1] + (leaves.i0 + k2) * spacing, o[2] + P.max(axis=1)], axis=1)
    return lo, hi


def cull_tilelets(heights: np.ndarray, leaves: Leaves, origin_rel, spacing: float, planes: np.ndarray) -> np.ndarray:
    """True for tilelets whose box lies wholly outside one of the planes (6, 4), a*x+b*y+c*z+d >= 0 inside."""
    lo, hi = tilelet_boxes(heights, leaves, origin_rel, spacing)
    planes = np.asarray(planes, dtype=np.float64)
    n = planes[:, :3]
    pos = np.where(n[None, :, :] >= 0, hi[:, None, :], lo[:, None, :])     # (count, 6, 3)
    dist = np.einsum("cpk,pk->cp", pos, n) + planes[None, :, 3]
    return np.any(dist < 0, axis=1)
