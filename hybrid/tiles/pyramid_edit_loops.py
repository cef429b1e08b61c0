"""One level of a tile pyramid following an edit, compiled by numba: the deviation blocks around the window, their
super-block maxima, the touched tiles' bounds and errors, and the level's caches over those tiles, in one call a
level where numpy made a few dozen small calls (``hybrid.tiles.pyramid_edit``). Same arithmetic in the same order
(maxima are exact; float64 sums and products as numpy makes them), so the values are equal bit for bit. Imported
where first called, so that a process that never edits does not load numba."""

from __future__ import annotations

import numpy as np
from numba import njit

from .bounds_loops import deviation_block_max
from .quantize_loops import step_of


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


@njit(cache=True)
def sample_block_bounds(h, s, a0, a1, b0, b1, zhi, zlo):
    """Highest and lowest sample of each block of s x s level-0 cells, block rows [a0, a1) and columns [b0, b1),
    its border samples included, into zhi, zlo in place."""
    cells_r, cells_c = h.shape[0] - 1, h.shape[1] - 1
    for a in range(a0, a1):
        for b in range(b0, b1):
            i0, j0 = a * s, b * s
            hi, lo = h[i0, j0], h[i0, j0]
            for i in range(i0, min(i0 + s, cells_r) + 1):
                for j in range(j0, min(j0 + s, cells_c) + 1):
                    hi, lo = max(hi, h[i, j]), min(lo, h[i, j])
            zhi[a, b], zlo[a, b] = hi, lo


@njit(cache=True)
def follow_level0(h, n, s, win, tiles, zblocks, zmax, zmin):
    """zmax, zmin of the touched level-0 tiles ``tiles`` (ty0, ty1, tx0, tx1) of n cells after the samples of
    ``win`` changed: the sample blocks of s x s cells around the window re-measured (``zblocks``: their highest
    and lowest), then each tile's from its (n / s)² blocks, in place."""
    zhi, zlo = zblocks
    i0, i1, j0, j1 = win
    a0, a1 = max((i0 - 1) // s, 0), min((i1 - 1) // s + 1, zhi.shape[0])
    b0, b1 = max((j0 - 1) // s, 0), min((j1 - 1) // s + 1, zhi.shape[1])
    sample_block_bounds(h, s, a0, a1, b0, b1, zhi, zlo)
    m = n // s
    for ty in range(tiles[0], tiles[1]):
        for tx in range(tiles[2], tiles[3]):
            zmax[ty, tx] = zhi[ty * m : (ty + 1) * m, tx * m : (tx + 1) * m].max()
            zmin[ty, tx] = zlo[ty * m : (ty + 1) * m, tx * m : (tx + 1) * m].min()


@njit(cache=True)
def follow_on_step(h, grown, src, on_step):
    """Per-cell on-step flags (every corner float32(offset + step k), ``quantize.on_step_cells``) of the cells
    whose corners lie in the sample window ``grown`` (i0, i1, j0, j1), in place; src: (step, offset)."""
    i0, i1, j0, j1 = grown
    ok = np.empty((i1 - i0, j1 - j0), np.bool_)
    for i in range(i0, i1):
        for j in range(j0, j1):
            ok[i - i0, j - j0] = step_of(h[i, j], src[0], src[1])[1]
    for i in range(i1 - i0 - 1):
        for j in range(j1 - j0 - 1):
            on_step[i0 + i, j0 + j] = ok[i, j] and ok[i, j + 1] and ok[i + 1, j] and ok[i + 1, j + 1]


@njit(cache=True)
def follow_on_tiles(on_step, n, level, tiles, flags, below):
    """Per-tile on-step flags of a level's touched tiles, in place: from the finer level's 2 x 2 ``below`` where it
    is kept (non-empty), else from every cell the tile covers."""
    k = n << level
    for ty in range(tiles[0], tiles[1]):
        for tx in range(tiles[2], tiles[3]):
            if below.size:
                flags[ty, tx] = below[2 * ty : 2 * ty + 2, 2 * tx : 2 * tx + 2].all()
            else:
                flags[ty, tx] = on_step[ty * k : (ty + 1) * k, tx * k : (tx + 1) * k].all()


@njit(cache=True)
def follow_pyramid(h, n, win, tiles, bounds, blocks, s, zblocks, on_step, grown, src, on_tiles, caches, geo, q):
    """Every level of a pyramid of n-cell tiles after the samples of ``win`` of h changed, in one call: per level l
    (``tiles[l]``: its touched tiles), ``bounds`` (zmax, zmin, err tuples a level), deviation ``blocks`` (dev, sup
    tuples, level 0 empty), the on-step flags (``on_step`` per cell over ``grown``, ``on_tiles`` a level; empty:
    not kept) and the caches (qerr, box_lo, box_hi, table tuples a level; empty: not made), in place. geo: the
    level-0 tile geometry (``follow_level_caches``); src: (step, offset) of the source, step <= 0: none."""
    zmax, zmin, err = bounds
    qerr, box_lo, box_hi, table = caches
    follow_level0(h, n, s, win, tiles[0], zblocks, zmax[0], zmin[0])
    for level in range(1, len(zmax)):
        dev, sup, t = blocks[0][level], blocks[1][level], tiles[level]
        follow_level_bounds(
            h,
            1 << level,
            win,
            dev,
            sup,
            s,
            t,
            zmax[0],
            zmin[0],
            zmax[level],
            zmin[level],
            err[level],
            err[level - 1],
            n // s,
        )
    if on_step.size:
        follow_on_step(h, grown, src, on_step)
    g = geo.copy()
    for level in range(len(zmax)):
        if on_step.size and on_tiles[level].size:
            below = on_tiles[level - 1] if level > 0 else on_tiles[level][:0, :0]
            follow_on_tiles(on_step, n, level, tiles[level], on_tiles[level], below)
        g[3], g[4] = geo[3] * (1 << level), geo[4] * (1 << level)
        lo, hi, e, on, t = zmin[level], zmax[level], err[level], on_tiles[level], tiles[level]
        follow_level_caches(t, g, lo, hi, e, on, src[0], q, qerr[level], box_lo[level], box_hi[level], table[level])
