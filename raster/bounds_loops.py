"""The per-level extremes of a tile's node block (``raster.host_nodes``), compiled by numba: one pass
over the block's inner nodes, where numpy took three reductions a level (two dozen calls a tile upload)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def level_extremes(data, offsets, n: int):
    """(largest effective error, smallest zlo, largest zhi) per local level (float64, metres) of a tile's node
    block ``data`` (count, 4) float32 with ``offsets``, its n-cell tile's levels with a one-node apron; NaN
    propagates as numpy's max and min."""
    levels = len(offsets) - 1
    err, zlo, zhi = np.empty(levels), np.empty(levels), np.empty(levels)
    for m in range(levels):
        side = n >> (m + 1)
        w, base = side + 2, offsets[m]
        e, lo, hi = data[base + w + 1, 0], data[base + w + 1, 1], data[base + w + 1, 2]
        for a in range(1, side + 1):
            for b in range(1, side + 1):
                i = base + a * w + b
                v0, v1, v2 = data[i, 0], data[i, 1], data[i, 2]
                if v0 > e or v0 != v0:
                    e = v0
                if v1 < lo or v1 != v1:
                    lo = v1
                if v2 > hi or v2 != v2:
                    hi = v2
        err[m], zlo[m], zhi[m] = e, lo, hi
    return err, zlo, zhi
