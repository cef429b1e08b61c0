"""A grid's coarser levels by subsampling: reductions over b x b blocks (a level's tile bounds and errors from its
children's, or from per-cell values) and the triangulated surface of every k-th sample, evaluated at every sample
(what a level's geometric error is measured against).
"""

from __future__ import annotations

import numpy as np


def block_reduce(a: np.ndarray, b: int, fn) -> np.ndarray:
    """Reduce a 2-D array over b x b blocks with the ufunc fn (np.maximum, np.minimum); the last blocks of each
    axis may be partial (ceil(shape / b) blocks a side)."""
    rows, cols = np.arange(0, a.shape[0], b), np.arange(0, a.shape[1], b)
    return fn.reduceat(fn.reduceat(a, rows, axis=0), cols, axis=1)


def interpolate_clamped(h: np.ndarray, k: int) -> np.ndarray:
    """Triangulated surface of the every-k-th-sample grid of h, edge-repeated beyond h, at every sample of h
    (float64); cells split along the (i, j) -> (i+1, j+1) diagonal; h may be any rectangle."""

    def axis(n):
        idx = np.arange(n)
        c = idx // k
        return np.minimum(c * k, n - 1), np.minimum((c + 1) * k, n - 1), (idx - c * k) / k

    r0, r1, fi = axis(h.shape[0])
    c0, c1, fj = axis(h.shape[1])
    h = h.astype(np.float64, copy=False)
    fi, fj = fi[:, None], fj[None, :]
    h00, h01 = h[np.ix_(r0, c0)], h[np.ix_(r0, c1)]
    h10, h11 = h[np.ix_(r1, c0)], h[np.ix_(r1, c1)]
    lower = h00 + fj * (h01 - h00) + fi * (h11 - h01)
    upper = h00 + fi * (h10 - h00) + fj * (h11 - h10)
    return np.where(fj >= fi, lower, upper)
