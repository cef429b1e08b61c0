"""One level of a tile pyramid following an edit, compiled by numba: the deviation blocks around the window, their
super-block maxima, the touched tiles' bounds and errors, and the level's caches over those tiles, in one call a
level where numpy made a few dozen small calls (``hybrid.tiles.pyramid_edit``). Same arithmetic in the same order
(maxima are exact; float64 sums and products as numpy makes them), so the values are equal bit for bit. Imported
where first called, so that a process that never edits does not load numba."""

from __future__ import annotations

import numpy as np
from numba import njit

from .bounds_loops import deviation_block_max


@njit(cache=True)
def follow_level_bounds(h, k, win, dev, sup, s, tiles, zmax0, zmin0, zmax, zmin, err, err_below, m):
    """Level with blocks of k x k level-0 cells after the samples of ``win`` (i0, i1, j0, j1) of h changed: its
    deviation blocks ``dev`` around the window, their s x s maxima ``sup`` over them, and zmax, zmin (from level 0's
    zmax0, zmin0) and err (from ``sup``, m super-blocks a tile side, and the finer level's ``err_below``) of the
    touched tiles ``tiles`` (ty0, ty1, tx0, tx1), in place."""
    i0, i1, j0, j1 = win
    # block a depends on samples [a k, (a + 1) k] only: the blocks whose closed range meets the window
    a0, a1 = max((i0 - 1) // k, 0), min((i1 - 1) // k + 1, dev.shape[0])
    b0, b1 = max((j0 - 1) // k, 0), min((j1 - 1) // k + 1, dev.shape[1])
    dev[a0:a1, b0:b1] = deviation_block_max(h, k, a0, a1, b0, b1)
    for r in range(a0 // s, -(-a1 // s)):
        for c in range(b0 // s, -(-b1 // s)):
            sup[r, c] = dev[r * s : (r + 1) * s, c * s : (c + 1) * s].max()
    for ty in range(tiles[0], tiles[1]):
        for tx in range(tiles[2], tiles[3]):
            zmax[ty, tx] = zmax0[ty * k : (ty + 1) * k, tx * k : (tx + 1) * k].max()
            zmin[ty, tx] = zmin0[ty * k : (ty + 1) * k, tx * k : (tx + 1) * k].min()
            mine = sup[ty * m : (ty + 1) * m, tx * m : (tx + 1) * m].max()
            below = err_below[2 * ty : 2 * ty + 2, 2 * tx : 2 * tx + 2].max()
            err[ty, tx] = max(mine, below)


@njit(cache=True)
def tile_qerr(lo, hi, step, on_tile, q_max, half_ulp):
    """One tile's quantisation bound, as ``TilePyramid.quantization_errors_at`` makes it (``quantize.error_bound``'s
    arithmetic): lo, hi its bounds (float32 metres), step the source step (<= 0: none), on_tile whether every cell
    it covers is on that step."""
    lo, hi = np.float64(lo), np.float64(hi)
    if step > 0.0 and on_tile and (hi - lo) / step <= q_max - 0.5:
        return 0.0
    return (hi - lo) / (2 * q_max) * (1 + 1e-9) + half_ulp * max(abs(lo), abs(hi))


@njit(cache=True)
def follow_level_caches(tiles, geo, zmin, zmax, err, on, step, q, qerr, box_lo, box_hi, table):
    """The level's caches over its touched tiles ``tiles`` (ty0, ty1, tx0, tx1), in place: quantisation bounds
    ``qerr``, boxes ``box_lo``/``box_hi`` ((rows, cols, 3) world metres) and the selection ``table`` ((rows, cols,
    7): box corners and error plus quantisation bound); an empty array is a cache not made. geo: (ox, oy, oz,
    span_x, span_y, x_end, y_end) metres; on: per tile on-step flags (empty: none); step: the source step (<= 0:
    none); q: (Q_MAX, half ulp)."""
    ox, oy, oz, span_x, span_y, x_end, y_end = geo
    for ty in range(tiles[0], tiles[1]):
        for tx in range(tiles[2], tiles[3]):
            if qerr.size:
                on_tile = on.size > 0 and on[ty, tx]
                qerr[ty, tx] = tile_qerr(zmin[ty, tx], zmax[ty, tx], step, on_tile, q[0], q[1])
            if box_lo.size:
                x0, y0 = ox + tx * span_x, oy + ty * span_y
                box_lo[ty, tx, 0], box_lo[ty, tx, 1], box_lo[ty, tx, 2] = x0, y0, oz + np.float64(zmin[ty, tx])
                box_hi[ty, tx, 0], box_hi[ty, tx, 1] = min(x0 + span_x, x_end), min(y0 + span_y, y_end)
                box_hi[ty, tx, 2] = oz + np.float64(zmax[ty, tx])
            if table.size:
                table[ty, tx, 0:3] = box_lo[ty, tx]
                table[ty, tx, 3:6] = box_hi[ty, tx]
                table[ty, tx, 6] = np.float64(err[ty, tx]) + qerr[ty, tx]
