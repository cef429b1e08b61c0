"""A tile's max mipmap of 16-bit codes (or float32 heights) on the host, compiled by numba: one pass a level where numpy made a
temporary array per maximum. Imported where first called, so that a process that never makes one does not load
numba."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def code_mip_levels(q):
    """Max-mip levels 1..log2 N of (N+1)² uint16 codes or float32 heights, level after level in one flat array of
    their dtype (level 1, (N/2)² texels, first): level 1 is the largest value of each 3 x 3 samples at stride 2,
    each next one a 2 x 2 maximum."""
    n = q.shape[0] - 1
    total, m = 0, n // 2
    while m >= 1:
        total += m * m
        m //= 2
    out = np.empty(total, q.dtype)
    m = n // 2
    for r in range(m):
        for c in range(m):
            best = q[2 * r, 2 * c]
            for i in range(2 * r, 2 * r + 3):
                for j in range(2 * c, 2 * c + 3):
                    best = max(best, q[i, j])
            out[r * m + c] = best
    start = 0
    while m > 1:
        half, nxt = m // 2, start + m * m
        for r in range(half):
            for c in range(half):
                a = start + 2 * r * m + 2 * c
                out[nxt + r * half + c] = max(out[a], out[a + 1], out[a + m], out[a + m + 1])
        start, m = nxt, half
    return out
