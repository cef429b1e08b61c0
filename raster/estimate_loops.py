"""The loop of ``raster.estimate.estimate_rows``, compiled by numba: a frame's tiles one at a time (a few dozen,
so numpy's per-call overhead was their cost). Imported where first called, so that a process that never plans
does not load numba."""

from __future__ import annotations

import numpy as np
from numba import njit

from .split_tables import BIN_SHIFT


@njit(cache=True)
def estimate_tiles(tables, base, rows, coarse, boxes, root, eye, k_tau, planes, inside, lean, beta, sides, weights):
    """``estimate_rows`` tile by tile: (triangles (B,) int64, visible share (B,)) of the stacked rows ``rows``;
    ``planes`` (6, 4) eye-relative frustum planes, or (0, 4) for none; ``weights`` the triangles a split level-1
    node and a near leaf add, with side errors and without (split1 both, then near both)."""
    w, bias = corner_test(planes, eye)
    b, kinds, nb = len(rows), tables.shape[1], tables.shape[2]
    nc = coarse.shape[1]
    tri, vis = np.zeros(b, np.int64), np.zeros(b)
    d = np.empty(nb + nc)
    factor = np.array([1.0, beta, 1.0]) / k_tau
    thr, counts = np.empty(nb, np.float32), np.empty(nb, np.int64)
    for t in range(b):
        r = rows[t]
        for n in range(nb + nc):  # eye to each box, metres
            dx = max(boxes[r, 3, n] - eye[0], eye[0] - boxes[r, 0, n], 0.0)
            dy = max(boxes[r, 4, n] - eye[1], eye[1] - boxes[r, 1, n], 0.0)
            dz = max(boxes[r, 5, n] - eye[2], eye[2] - boxes[r, 2, n], 0.0)
            d[n] = np.sqrt(dx * dx + dy * dy + dz * dz)
        per_kind = np.zeros(kinds)
        splits = shown = 0.0
        for k in range(kinds):  # small nodes: one table look-up a block
            for n in range(nb):
                thr[n] = d[n] * factor[k]
            block_splits(tables[r, k], base[r], thr, counts)
            for n in range(nb):
                count = counts[n]
                per_kind[k] += count
                if k == 0:
                    splits += count
                    shown += count * _seen(boxes, r, n, w, bias, inside[t])
        near_large = 0.0
        for c in range(nc):  # large nodes: each against its own box
            if coarse[r, c] * k_tau > d[nb + c]:
                splits += 1
                shown += _seen(boxes, r, nb + c, w, bias, inside[t])
            near_large += coarse[r, c] * (k_tau / beta) > d[nb + c]
        leaves = 1 + 3 * (splits + root[r])
        vis[t] = min(1.0, (1 + 3 * (shown + root[r])) / leaves)
        if not lean:
            tri[t] = 8 * leaves
            continue
        near = per_kind[1] / sides[r] - splits + near_large  # near leaves
        weight = weights[2] if sides[r] == 4 else weights[3]
        split1 = weights[0] if sides[r] == 4 else weights[1]
        tri[t] = np.int64(np.rint(4 * leaves + weight * near + split1 * per_kind[2]))
    return tri, vis


@njit(cache=True)
def corner_test(planes, eye):
    """(6, 6) weights and (6,) bounds such that a (hi, lo) world box row r lies wholly behind some frustum plane
    (eye-relative ``planes`` (6, 4)) exactly where some column of r @ weights falls below its bound: per plane, its
    corner farthest along the normal. No planes ((0, 4)): bounds that every box passes."""
    w, bias = np.zeros((6, 6)), np.full(6, -np.inf)
    if planes.shape[0] == 0:
        return w, bias
    for p in range(6):
        bias[p] = -planes[p, 3]
        for j in range(3):
            n = planes[p, j]
            w[j, p], w[3 + j, p] = max(n, 0.0), min(n, 0.0)
            bias[p] += eye[j] * n
    return w, bias


@njit(cache=True)
def _seen(boxes, r: int, n: int, w, bias, inside: bool) -> float:
    """1.0 where stacked row r's box n is not wholly behind any frustum plane (``corner_test``), else 0.0."""
    if inside:
        return 1.0
    for p in range(6):
        s = 0.0
        for j in range(6):
            s += w[j, p] * boxes[r, j, n]
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
