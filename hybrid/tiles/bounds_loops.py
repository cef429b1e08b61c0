"""The deviation of a coarse level's surface from the level-0 samples, per block, compiled by numba: one pass
over the samples where numpy made a dozen temporary arrays (``hybrid.tiles.bounds._deviation``, its corner
maximum and block reduction). Same arithmetic in the same order, so the values are equal bit for bit. Imported
where first called, so that a process that never edits does not load numba."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _surface(h, k, i, j):
    """The triangulated every-k-th-sample surface of h (edge-repeated) at sample (i, j), float64 metres."""
    rows, cols = h.shape
    ci, cj = i // k, j // k
    r0, r1 = min(ci * k, rows - 1), min((ci + 1) * k, rows - 1)
    c0, c1 = min(cj * k, cols - 1), min((cj + 1) * k, cols - 1)
    fi, fj = (i - ci * k) / k, (j - cj * k) / k
    h00, h01 = np.float64(h[r0, c0]), np.float64(h[r0, c1])
    h10, h11 = np.float64(h[r1, c0]), np.float64(h[r1, c1])
    if fj >= fi:
        return h00 + fj * (h01 - h00) + fi * (h11 - h01)
    return h00 + fi * (h10 - h00) + fj * (h11 - h10)


@njit(cache=True)
def deviation_block_max(h, k, a0, a1, b0, b1):
    """Per block of k x k level-0 cells, block rows [a0, a1) and columns [b0, b1): the largest |surface - h| over
    the samples of its cells (a block's cells' corners), float64 metres."""
    cells_r, cells_c = h.shape[0] - 1, h.shape[1] - 1
    out = np.zeros((a1 - a0, b1 - b0))
    for bi in range(a0, a1):
        i0, i1 = bi * k, min((bi + 1) * k, cells_r)
        for bj in range(b0, b1):
            j0, j1 = bj * k, min((bj + 1) * k, cells_c)
            best = 0.0
            for i in range(i0, i1 + 1):
                for j in range(j0, j1 + 1):
                    best = max(best, abs(_surface(h, k, i, j) - np.float64(h[i, j])))
            out[bi - a0, bj - b0] = best
    return out
