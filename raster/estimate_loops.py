"""The loop of ``raster.estimate.estimate_rows``, compiled by numba: a frame's tiles one at a time (a few dozen,
so numpy's per-call overhead was their cost). Imported where first called, so that a process that never plans
does not load numba."""

from __future__ import annotations

import numpy as np
from numba import njit

from .split_tables import BIN_SHIFT


@njit(cache=True)
def estimate_tiles(tables, base, rows, coarse, boxes, root, eye, k_tau, w, bias, inside, lean, beta, sides, weights):
    """``estimate_rows`` tile by tile: (triangles (B,) int64, visible share (B,)); ``weights`` the triangles a split
    level-1 node and a near leaf add, with side errors and without (split1 both, then near both)."""
    b, kinds, nb = len(rows), tables.shape[1], tables.shape[2]
    nc = coarse.shape[1]
    tri, vis = np.zeros(b, np.int64), np.zeros(b)
    d = np.empty(nb + nc)
    factor = np.array([1.0, beta, 1.0]) / k_tau
    thr, counts = np.empty(nb, np.float32), np.empty(nb, np.int64)
    for t in range(b):
        for n in range(nb + nc):  # eye to each box, metres
            dx = max(boxes[t, 3, n] - eye[0], eye[0] - boxes[t, 0, n], 0.0)
            dy = max(boxes[t, 4, n] - eye[1], eye[1] - boxes[t, 1, n], 0.0)
            dz = max(boxes[t, 5, n] - eye[2], eye[2] - boxes[t, 2, n], 0.0)
            d[n] = np.sqrt(dx * dx + dy * dy + dz * dz)
        per_kind = np.zeros(kinds)
        splits = shown = 0.0
        for k in range(kinds):  # small nodes: one table look-up a block
            for n in range(nb):
                thr[n] = d[n] * factor[k]
            block_splits(tables[rows[t], k], base[rows[t]], thr, counts)
            for n in range(nb):
                count = counts[n]
                per_kind[k] += count
                if k == 0:
                    splits += count
                    shown += count * _seen(boxes, t, n, w, bias, inside[t])
        near_large = 0.0
        for c in range(nc):  # large nodes: each against its own box
            if coarse[t, c] * k_tau > d[nb + c]:
                splits += 1
                shown += _seen(boxes, t, nb + c, w, bias, inside[t])
            near_large += coarse[t, c] * (k_tau / beta) > d[nb + c]
        leaves = 1 + 3 * (splits + root[t])
        vis[t] = min(1.0, (1 + 3 * (shown + root[t])) / leaves)
        if not lean:
            tri[t] = 8 * leaves
            continue
        near = per_kind[1] / sides[t] - splits + near_large  # near leaves
        weight = weights[2] if sides[t] == 4 else weights[3]
        split1 = weights[0] if sides[t] == 4 else weights[1]
        tri[t] = np.int64(np.rint(4 * leaves + weight * near + split1 * per_kind[2]))
    return tri, vis


@njit(cache=True)
def _seen(boxes, t: int, n: int, w, bias, inside: bool) -> float:
    """1.0 where tile t's box n is not wholly behind any frustum plane (``_corner_test``), else 0.0."""
    if inside:
        return 1.0
    for p in range(6):
        s = 0.0
        for j in range(6):
            s += w[j, p] * boxes[t, j, n]
        if s < bias[p]:
            return 0.0
    return 1.0


@njit(cache=True)
def block_splits(table, base: int, thr, out) -> None:
    """Into ``out`` (blocks,): each block's nodes of one kind whose error, rounded to a bin edge, exceeds its
    threshold ``thr`` (blocks,) (float32 metres); ``table`` (blocks, TABLE_BINS) is one tile's ``split_tables``
    of that kind and ``base`` its base bin. One look-up a block; the table's ends count all and none, exactly."""
    width = table.shape[1]
    bins = (thr.view(np.int32).astype(np.int64) >> BIN_SHIFT) - base
    for n in range(len(thr)):
        out[n] = table[n, min(max(bins[n], 0), width - 1)]


@njit(cache=True)
def kind_splits(tables, base, rows, threshold):
    """``block_splits`` of many tiles: per tile row, kind and block (B, kinds, blocks) int64 counts, from stacked
    tables (rows, kinds, blocks, TABLE_BINS), base bins (rows,), rows (B,) and thresholds (B, kinds, blocks)
    in metres."""
    out = np.zeros(threshold.shape, np.int64)
    for b in range(threshold.shape[0]):
        for k in range(threshold.shape[1]):
            block_splits(tables[rows[b], k], base[rows[b]], threshold[b, k].astype(np.float32), out[b, k])
    return out
