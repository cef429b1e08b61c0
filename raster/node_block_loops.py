"""The measuring loop of ``raster.node_blocks``, compiled by numba: a window's samples one at a time (see that
module). Imported where first called, so that a process that never edits does not load numba."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True)
def _at(h, i: int, j: int) -> float:
    """The padded square's sample (row i, column j) of the grid h as float64: beyond the grid its edge repeats."""
    return np.float64(h[min(i, h.shape[0] - 1), min(j, h.shape[1] - 1)])


@njit(cache=True)
def _deviations(h, r: int, c: int, m: int, n: int) -> tuple:
    """(|full - h|, |stitched - h|) in metres of level-m nodes (posts every k = 2^m samples, side 2k) of an
    n-cell square at sample (r, c): ``hybrid.tiles.fans.fans_at``'s operations in its order, for one sample."""
    k, s = 1 << m, 2 << m
    ir, ic = min(r >> m, (n >> m) - 1), min(c >> m, (n >> m) - 1)
    fi, fj = (r - ir * k) / k, (c - ic * k) / k
    h00, h01 = _at(h, ir * k, ic * k), _at(h, ir * k, ic * k + k)
    h10, h11 = _at(h, ir * k + k, ic * k), _at(h, ir * k + k, ic * k + k)
    if (ir + ic) & 1:
        if fi + fj <= 1.0:
            full = h00 + fj * (h01 - h00) + fi * (h10 - h00)
        else:
            full = h11 + (1.0 - fj) * (h10 - h11) + (1.0 - fi) * (h01 - h11)
    elif fj >= fi:
        full = h00 + fj * (h01 - h00) + fi * (h11 - h01)
    else:
        full = h00 + fi * (h10 - h00) + fj * (h11 - h10)
    ar, ac = min(r >> (m + 1), (n >> (m + 1)) - 1), min(c >> (m + 1), (n >> (m + 1)) - 1)
    v, u = (r - ar * s) / k, (c - ac * s) / k
    sw, se = _at(h, ar * s, ac * s), _at(h, ar * s, ac * s + s)
    nw, ne = _at(h, ar * s + s, ac * s), _at(h, ar * s + s, ac * s + s)
    cc = _at(h, ar * s + k, ac * s + k)
    if v <= u:
        if v <= 2.0 - u:
            st = sw + 0.5 * u * (se - sw) + v * (cc - 0.5 * (sw + se))
        else:
            st = se + 0.5 * v * (ne - se) + (2.0 - u) * (cc - 0.5 * (se + ne))
    elif v <= 2.0 - u:
        st = sw + 0.5 * v * (nw - sw) + u * (cc - 0.5 * (sw + nw))
    else:
        st = nw + 0.5 * u * (ne - nw) + (2.0 - v) * (cc - 0.5 * (nw + ne))
    own = _at(h, r, c)
    return abs(full - own), abs(st - own)


@njit(cache=True, parallel=True)
def measure_blocks(h, m: int, n: int, lb: int, side_errors: bool, p0: int, p1: int, q0: int, q1: int, out) -> None:
    """Sub-block maxima (``_measure``) into out (channels, nbr, nbc), zeros on entry: each row of sub-blocks on its
    own thread, every sample of its rows once (the rows on its borders also by its neighbour), its deviations
    added to each sub-block holding it (two on sub-block borders), the triangle masks in the coordinates of that
    sub-block's node (``hybrid.tiles.fans.side_maxima``'s); level m, sub-blocks of 2^lb."""
    k, B = 1 << m, 1 << lb
    mask = (2 << m) - 1
    nbc = (q1 - q0) >> lb
    for a in prange((p1 - p0) >> lb):
        base = p0 + a * B
        for r in range(base, base + B + 1):
            v = ((base & mask) + r - base) / k
            for c in range(q0, q1 + 1):
                df, ds = _deviations(h, r, c, m, n)
                e = df if side_errors else max(df, ds)
                for b in range(max((c - q0 - 1) >> lb, 0), min((c - q0) >> lb, nbc - 1) + 1):
                    out[0, a, b] = max(out[0, a, b], e)
                    if not side_errors:
                        continue
                    u = (((q0 + b * B) & mask) + c - q0 - b * B) / k
                    if v >= u and v <= 2.0 - u:
                        out[1, a, b] = max(out[1, a, b], ds)
                    if v <= u and v >= 2.0 - u:
                        out[2, a, b] = max(out[2, a, b], ds)
                    if v <= u and v <= 2.0 - u:
                        out[3, a, b] = max(out[3, a, b], ds)
                    if v >= u and v >= 2.0 - u:
                        out[4, a, b] = max(out[4, a, b], ds)
