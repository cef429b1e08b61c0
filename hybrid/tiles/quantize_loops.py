"""The passes of ``hybrid.tiles.quantize.quantize`` compiled by numba: one pass over a tile's samples for each
question (range, steps, codes) where numpy made a temporary array per operation. The arithmetic is the same,
float64 rounded once to float32 where the numpy form casts, so the codes and errors are equal bit for bit.
Imported where first called, so that a process that never quantises does not load numba."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def step_of(h, step, offset):
    """(k, on) of one float32 height h on a source's step: the nearest step index k (float64) and whether
    float32(offset + step k) is h. The edits' compiled follows (``raycast.edit_loops``, ``pyramid_edit_loops``)
    call it too, so that their codes and flags are this arithmetic's."""
    k = np.rint((np.float64(h) - offset) / step)
    return k, np.float32(offset + step * k) == h


@njit(cache=True, inline="always")
def range_code(v, lo, step, q_max):
    """The range code (float64, 0..q_max) of height v (float64 metres) over the range from ``lo`` in ``step``s."""
    return min(max(np.rint((v - lo) / step), 0.0), q_max)


@njit(cache=True, inline="always")
def range_error(v, lo, step, c):
    """|v - float32(lo + step * c)|: how far range code c lies from height v (float64 metres)."""
    return abs(np.float64(np.float32(lo + step * (c + 0.0))) - v)


@njit(cache=True)
def height_range(h):
    """(lowest, highest) of a 2-D float32 array, as float64."""
    lo, hi = np.inf, -np.inf
    for i in range(h.shape[0]):
        for j in range(h.shape[1]):
            v = np.float64(h[i, j])
            lo, hi = min(lo, v), max(hi, v)
    return lo, hi


@njit(cache=True)
def step_codes(h, step, offset, q_max):
    """Codes on a source's step: (codes (uint16, h's shape), base, ok). ok where every height is
    float32(offset + step * k) for an integer k and the ks span at most ``q_max`` from the least, base."""
    rows, cols = h.shape
    k = np.empty((rows, cols))
    kmin, kmax = np.inf, -np.inf
    for i in range(rows):
        for j in range(cols):
            v, on = step_of(h[i, j], step, offset)
            if not on:
                return np.zeros((0, 0), np.uint16), 0, False
            k[i, j] = v
            kmin, kmax = min(kmin, v), max(kmax, v)
    if kmax - kmin > q_max or not abs(kmin) < 2.0**31:
        return np.zeros((0, 0), np.uint16), 0, False
    q = np.empty((rows, cols), np.uint16)
    for i in range(rows):
        for j in range(cols):
            q[i, j] = np.uint16(k[i, j] - kmin)
    return q, np.int64(kmin), True


@njit(cache=True)
def range_codes(h, lo, step, q_max):
    """Codes over the range from ``lo`` in steps of ``step`` metres: (codes (uint16), largest |height -
    float32(lo + step * code)| in metres)."""
    rows, cols = h.shape
    q = np.empty((rows, cols), np.uint16)
    err = 0.0
    for i in range(rows):
        for j in range(cols):
            v = np.float64(h[i, j])
            c = range_code(v, lo, step, q_max)
            q[i, j] = np.uint16(c)
            err = max(err, range_error(v, lo, step, c))
    return q, err
