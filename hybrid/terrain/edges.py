"""Whether a ray starts under the terrain sheet: the terrain's outer edges and the eye against the ground.

The reference draws the terrain as a two-sided sheet without side walls, so a ray that starts under it (an
eye below the ground, or a ray entering the footprint below the terrain's outer edge) shows the underside
where it first comes up through the surface, and nothing hangs below the sheet. Terrain grid space: x, y in
level-0 texels of the whole terrain (sample (i, j) at (j, i)), z metres relative to the terrain's origin z;
the footprint is [0, cols - 1] x [0, rows - 1]. A ray starting over the footprint starts under when the eye
lies below the triangulated ground; one from outside when it enters the footprint below the outer edge's
height there (linear between samples, as the surface). GPU twin: hybrid/gl/edges.glsl.
"""

from __future__ import annotations

import numpy as np

from hybrid.terrain.heightfield import HeightField


def edge_profiles(heights: np.ndarray) -> np.ndarray:
    """(4, L) float32 heights (metres) along the south, north, west and east edges, L = max(rows, cols), each
    padded with its last sample."""
    sides = tuple(
        np.asarray(heights[i], dtype=np.float32)
        for i in ((0, slice(None)), (-1, slice(None)), (slice(None), 0), (slice(None), -1))
    )
    n = max(heights.shape)  # sliced first: a stored grid reads only its edges
    return np.stack([np.pad(s, (0, n - len(s)), mode="edge") for s in sides])


def grid_frame(hf: HeightField, eye, dirs) -> tuple[np.ndarray, np.ndarray]:
    """Eye (3,) and directions (M x 3) of world rays eye + t dirs (metres) in terrain grid space."""
    sx, sy = float(hf.spacing_x), float(hf.spacing_y)
    e = np.asarray(eye, dtype=np.float64) - np.asarray(hf.origin, dtype=np.float64)
    d = np.atleast_2d(np.asarray(dirs, dtype=np.float64))
    return np.array([e[0] / sx, e[1] / sy, e[2]]), np.stack([d[:, 0] / sx, d[:, 1] / sy, d[:, 2]], 1)


def over_footprint(hf: HeightField, O) -> bool:
    """Whether the point O (terrain grid space, ``grid_frame``) lies over the terrain's footprint."""
    return bool(0.0 <= O[0] <= hf.cols - 1 and 0.0 <= O[1] <= hf.rows - 1)


def eye_under(hf: HeightField, eye) -> bool:
    """True if the eye (world metres) lies over the terrain's footprint and below its triangulated ground."""
    O = grid_frame(hf, eye, np.zeros((1, 3)))[0]
    return over_footprint(hf, O) and bool(O[2] < float(hf.sample_triangles(O[1], O[0])))


def may_start_under(hf: HeightField, eye) -> bool:
    """Whether any ray from the eye (world metres) can start under the terrain sheet: over the footprint, when
    the eye is below the ground there; from outside it, always (a ray may enter through the side, below the
    outer edge)."""
    O = grid_frame(hf, eye, np.zeros((1, 3)))[0]
    return eye_under(hf, eye) if over_footprint(hf, O) else True


def starts_under(hf: HeightField, eye, dirs) -> np.ndarray:
    """Per world ray eye + t dirs (dirs M x 3): True if the ray starts under the terrain sheet."""
    O, D = grid_frame(hf, eye, dirs)
    if over_footprint(hf, O):
        return np.full(len(D), eye_under(hf, eye))
    cells = np.array([hf.cols - 1, hf.rows - 1], dtype=np.float64)
    M = len(D)
    tn, tf = np.full(M, -np.inf), np.full(M, np.inf)
    xside = np.zeros(M, bool)
    dead = np.zeros(M, bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for a in (0, 1):
            nz = D[:, a] != 0
            ta, tb = -O[a] / D[:, a], (cells[a] - O[a]) / D[:, a]
            lo = np.minimum(ta, tb)
            upd = nz & (lo > tn)
            tn = np.where(upd, lo, tn)
            xside = np.where(upd, a == 0, xside)
            tf = np.where(nz, np.minimum(tf, np.maximum(ta, tb)), tf)
            dead |= ~nz & ((O[a] < 0) | (O[a] > cells[a]))
    dead |= (tn > tf) | (tf < 0)
    P = O + np.where(dead, 0.0, tn)[:, None] * D
    side = np.where(xside, np.where(D[:, 0] > 0, 2, 3), np.where(D[:, 1] > 0, 0, 1))
    pos = np.where(xside, np.clip(P[:, 1], 0, cells[1]), np.clip(P[:, 0], 0, cells[0]))
    prof = edge_profiles(hf.heights).astype(np.float64)
    k = np.clip(np.floor(pos).astype(np.int64), 0, prof.shape[1] - 2)
    f = pos - k
    h = prof[side, k] * (1 - f) + prof[side, k + 1] * f
    return ~dead & (P[:, 2] < h)
