"""An exact CPU intersection of pixel rays with the full-resolution surface, the check on the reference renderer.

Independent of every renderer's code: each ray's ground track is walked cell by cell (every crossing of a grid
line, in order), and the two triangles of each cell it crosses (SW-NE diagonal, the reference's convention) are
intersected in float64 (Moller-Trumbore). Only the samples at the crossed cells' corners are read, so a grid held
in a tile store is never loaded whole.
"""

from __future__ import annotations

import numpy as np

CELLS_AT_ONCE = 1 << 16  # cells intersected in one vectorized pass of a ray


def _slab(o: float, d: float, lo: float, hi: float) -> tuple[float, float]:
    if abs(d) < 1e-300:
        return (-np.inf, np.inf) if lo <= o <= hi else (np.inf, -np.inf)
    a, b = (lo - o) / d, (hi - o) / d
    return min(a, b), max(a, b)


def _track(o, d, t0: float, t1: float, rows: int, cols: int) -> np.ndarray:
    """Cells (row, col) crossed by the ground track of texel-space ray o + t d for t in [t0, t1], in order."""
    ts = [np.array([t0, t1])]
    for axis in (0, 1):
        if abs(d[axis]) > 1e-300:
            a, b = sorted((o[axis] + t0 * d[axis], o[axis] + t1 * d[axis]))
            lines = np.arange(np.ceil(a), np.floor(b) + 1)
            ts.append((lines - o[axis]) / d[axis])
    t = np.unique(np.clip(np.concatenate(ts), t0, t1))
    mid = 0.5 * (t[:-1] + t[1:]) if len(t) > 1 else t
    col = np.clip(np.floor(o[0] + mid * d[0]), 0, cols - 2).astype(np.int64)
    row = np.clip(np.floor(o[1] + mid * d[1]), 0, rows - 2).astype(np.int64)
    return np.stack([row, col], axis=1)


def _nearest(eye, D, P) -> float:
    """Smallest t > 0 where ray eye + t D meets a triangle of P (k, 3, 3) world corners, inf if none."""
    v0, e1, e2 = P[:, 0], P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    p = np.cross(D, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-300
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = eye - v0
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ D) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return float(t[hit].min()) if hit.any() else np.inf


def _ray_distance(hf, eye, D, near: float, far: float) -> float:
    ox, oy, oz = (float(v) for v in hf.origin)
    sx, sy = hf.spacing_x, hf.spacing_y
    lo, hi = hf.height_range
    o = np.array([(eye[0] - ox) / sx, (eye[1] - oy) / sy])
    d = np.array([D[0] / sx, D[1] / sy])
    spans = [
        _slab(o[0], d[0], 0.0, hf.cols - 1),
        _slab(o[1], d[1], 0.0, hf.rows - 1),
        _slab(eye[2] - oz, D[2], lo, hi),
        (near, far),
    ]
    t0, t1 = max(s[0] for s in spans), min(s[1] for s in spans)
    if not t0 <= t1:
        return np.inf
    cells = _track(o, d, t0, t1, hf.rows, hf.cols)
    for k in range(0, len(cells), CELLS_AT_ONCE):
        r, c = cells[k : k + CELLS_AT_ONCE].T
        corners = [(r, c), (r, c + 1), (r + 1, c + 1), (r + 1, c)]
        P = np.stack(
            [
                np.stack([ox + cc * sx, oy + rr * sy, oz + np.asarray(hf.heights[rr, cc], np.float64)], -1)
                for rr, cc in corners
            ],
            axis=1,
        )
        t = min(_nearest(eye, D, P[:, [0, 1, 2]]), _nearest(eye, D, P[:, [0, 2, 3]]))
        if np.isfinite(t):
            return t
    return np.inf


def exact_distances(hf, view, rows, cols) -> np.ndarray:
    """Eye-to-surface distance (metres, float64; inf for a miss) of the rays through pixel centres (rows from the
    top, cols), against the full-resolution surface of hf between the view's near and far planes."""
    dirs = view.pixel_rays(np.asarray(rows), np.asarray(cols))
    fwd = view.forward
    out = np.full(len(dirs), np.inf)
    for k, D in enumerate(dirs):
        cos = float(D @ fwd)
        out[k] = _ray_distance(hf, view.eye, D, view.near / cos, view.far / cos)
    return out
