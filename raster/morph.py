"""Geomorph factors of tilelet posts.

A post that vanishes at the next coarser level (a leaf's edge midpoint or centre) is drawn at
``mix(own height, coarser surface height, alpha)``. The coarser surface at an edge midpoint is the mean of
the edge's two corners; at the centre it is the mean of the two corners on the diagonal through the
parent's centre. alpha comes from the tile tolerance t (metres) and the effective error E of the node(s)
whose split created the post (raster.quadtree): ``alpha = clamp((t / E - beta) / (1 - beta), 0, 1)``.

Why this is continuous: a node splits exactly when t falls below its E, and then t / E = 1, so its
children start fully morphed (alpha = 1, drawn on the parent's surface). As the eye approaches, t falls and
alpha drops to 0 at t = beta * E. A leaf can only split once t < its own E <= beta * E(parent or any
coarser node touching its edges) (the effective errors are built that way), so every midpoint it shares is
already at alpha = 0 when it turns into a finer leaf's unmorphed corner. Both leaves along a shared edge
use E = min of their parents' errors, so they compute the same alpha. Across tile borders (two tolerances)
the larger of the two sides' factors is used, which is still continuous but only exact within a tile.
"""

from __future__ import annotations

import numpy as np

# A turning cell (lean full-resolution leaves, select.comp.glsl LEAN_FULL_RES) turns while the larger morph factor
# of its two edge midpoints runs from TURN_FROM to 1, where the midpoint drops: the same continuity as over the
# whole range, with fewer cells turning at a time (each draws 4 triangles instead of 2).
TURN_FROM = 0.5


def morph_factor(tolerance: float, error, beta: float) -> np.ndarray:
    """alpha in [0, 1] for tolerance (metres) against node error(s) (metres); 1 = fully on the coarser surface."""
    e = np.asarray(error, dtype=np.float64)
    t = float(tolerance)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(e > 0, t / np.where(e > 0, e, 1.0), np.where(t > 0, np.inf, 1.0))
    return np.clip((ratio - beta) / (1.0 - beta), 0.0, 1.0)


def morphed_posts(
    posts: np.ndarray, i0: np.ndarray, j0: np.ndarray, level: np.ndarray, alpha: np.ndarray
) -> np.ndarray:
    """CPU mirror of the vertex shader: (count, 3, 3) post heights (metres) after geomorphing with alpha (count, 5)."""
    P = np.array(posts, dtype=np.float64)
    a = np.asarray(alpha, dtype=np.float64)
    lerp = lambda x, y, t: x + (y - x) * t  # noqa: E731
    out = P.copy()
    out[:, 1, 0] = lerp(P[:, 1, 0], 0.5 * (P[:, 0, 0] + P[:, 2, 0]), a[:, 0])  # W
    out[:, 1, 2] = lerp(P[:, 1, 2], 0.5 * (P[:, 0, 2] + P[:, 2, 2]), a[:, 1])  # E
    out[:, 0, 1] = lerp(P[:, 0, 1], 0.5 * (P[:, 0, 0] + P[:, 0, 2]), a[:, 2])  # S
    out[:, 2, 1] = lerp(P[:, 2, 1], 0.5 * (P[:, 2, 0] + P[:, 2, 2]), a[:, 3])  # N
    m = np.asarray(level)
    qx = (np.asarray(j0) >> (m + 1)) & 1
    qy = (np.asarray(i0) >> (m + 1)) & 1
    diag = np.where(qx == qy, 0.5 * (P[:, 0, 0] + P[:, 2, 2]), 0.5 * (P[:, 0, 2] + P[:, 2, 0]))
    out[:, 1, 1] = lerp(P[:, 1, 1], diag, a[:, 4])
    return out


def turn_factor(alpha) -> np.ndarray:
    """A cell's turn in [0, 1] (0: the reference's SW-NE diagonal, 1: the fan's) from the larger morph factor of
    its two edge midpoints: 0 up to TURN_FROM, then linear to 1 at 1."""
    return np.clip((np.asarray(alpha, dtype=np.float64) - TURN_FROM) / (1.0 - TURN_FROM), 0.0, 1.0)
