"""The hybrid's per-frame choice compiled by numba: terms, predicted ms and the hedged pick of every tile in one
call. A frame has a few dozen tiles, so the numpy form (``hybrid.cost.model.all_term_values``,
``CostModel.predict_terms``, ``hybrid.cost.planner.hedged_picks``), a few dozen small array calls, cost more than
the arithmetic; this is the same computation a tile and a subset at a time, and the numpy form stays as the
reference (``plan_frame(batch=False)``) that tests hold it to. Imported where first called, so that a process that
never plans does not load numba."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def term_table(pixels, triangles, visible, surface_pixels, slab_cells):
    """(B, 6) term values in ``hybrid.cost.model.ALL_TERMS`` order from (B,) feature columns (NaN triangles kept)."""
    b = len(pixels)
    out = np.empty((b, 6))
    for i in range(b):
        out[i, 0] = 1.0
        out[i, 1] = triangles[i]
        out[i, 2] = triangles[i] * visible[i]
        out[i, 3] = pixels[i]
        out[i, 4] = surface_pixels[i]
        out[i, 5] = pixels[i] * np.log2(1.0 + slab_cells[i])
    return out


@njit(cache=True)
def predicted_table(terms, coef, uses_triangles, unknown):
    """(S, B) predicted ms from (B, 6) terms and (S, 6) coefficients; a strategy with triangle terms
    (``uses_triangles`` (S,)) gets ``unknown`` where a tile's triangles are NaN, the others leave them out."""
    s_count, b = coef.shape[0], terms.shape[0]
    out = np.empty((s_count, b))
    for i in range(b):
        missing = np.isnan(terms[i, 1])
        for s in range(s_count):
            if missing and uses_triangles[s]:
                out[s, i] = unknown
                continue
            acc = 0.0
            for t in range(6):
                if not (missing and (t == 1 or t == 2)):
                    acc += coef[s, t] * terms[i, t]
            out[s, i] = acc
    return out


@njit(cache=True)
def hedged_pick_loop(table, overhead, err, tile_err, mixed, mix_error, masks):
    """``hybrid.cost.planner.hedged_picks`` of an (S, B) table of predicted ms: (B,) strategy indices; ``masks``
    (K, S) the non-empty subsets in ``hybrid.cost.choice._subsets`` order."""
    s_count, b = table.shape
    if b == 0:
        return np.zeros(0, np.int64)
    known = np.ones(b, np.bool_)
    for i in range(b):
        for s in range(s_count):
            if not np.isfinite(table[s, i]):
                known[i] = False
    base, best = 0, np.inf
    for s in range(s_count):  # the cheapest pure frame over the tiles every strategy can draw
        total = 0.0
        for i in range(b):
            if known[i]:
                total += table[s, i]
        total += overhead[s]  # summed in numpy's order, so that ties break alike
        if total < best or s == 0:
            base, best = s, total
    factor = np.empty(s_count)
    for s in range(s_count):
        factor[s] = 1.0 if s == base else 1.0 + tile_err[s] + tile_err[base]
    all_known = known.all()
    if all_known and _base_wins(table, factor, base, overhead, mixed):
        return np.full(b, base, np.int64)
    order = np.empty(s_count, np.int64)
    order[0] = base
    k = 1
    for s in range(s_count):
        if s != base:
            order[k] = s
            k += 1
    picks = _best_subset(table, factor, order, overhead, mixed, masks)
    margin = max(err[base], mix_error)
    pure = picks.copy()
    differs = False
    for i in range(b):
        if known[i]:
            pure[i] = base
        differs = differs or pure[i] != picks[i]
    if margin > 0 and differs:
        mixed_ms = _frame_ms(table, picks, overhead, mixed)
        pure_ms = _frame_ms(table, pure, overhead, mixed)
        if pure_ms - mixed_ms < margin * pure_ms:
            return pure
    return picks


@njit(cache=True)
def _base_wins(table, factor, base, overhead, mixed):
    """``hybrid.cost.planner._pure_base_wins`` on the table scaled by ``factor``."""
    if mixed < 0 or overhead.min() < 0:
        return False
    for s in range(table.shape[0]):
        if s == base:
            continue
        gain = 0.0
        for i in range(table.shape[1]):
            gain += max(table[base, i] * factor[base] - table[s, i] * factor[s], 0.0)
        if gain + overhead[base] > overhead[s]:
            return False
    return True


@njit(cache=True)
def _best_subset(table, factor, order, overhead, mixed, masks):
    """``hybrid.cost.choice.best_assignment_table`` of the scaled table's rows in ``order`` (no measured frames):
    (B,) picks as indices of the unordered table."""
    s_count, b = table.shape
    n_sub = masks.shape[0]
    picks = np.zeros((n_sub, b), np.int64)
    totals = np.empty(n_sub)
    for k in range(n_sub):
        used = np.zeros(s_count, np.bool_)
        tiles, size = 0.0, 0
        for j in range(s_count):
            size += masks[k, j]
        for i in range(b):
            bj, bv = 0, np.inf  # all infinite: the first strategy, as numpy's argmin
            for j in range(s_count):
                v = table[order[j], i] * factor[order[j]]
                if masks[k, j] and v < bv:
                    bj, bv = j, v
            picks[k, i] = bj
            used[bj] = True
            tiles += bv
        paid, n_used = 0.0, 0
        for j in range(s_count):
            if used[j]:
                paid += overhead[order[j]]
                n_used += 1
        total = tiles + paid + (mixed if size > 1 else 0.0)
        totals[k] = total if n_used == size else np.inf  # some strategy unused: priced as a smaller set
    least = totals.min()
    k = 0
    while totals[k] > least + 1e-12:
        k += 1
    out = np.empty(b, np.int64)
    for i in range(b):
        out[i] = order[picks[k, i]]
    return out


@njit(cache=True)
def _frame_ms(table, picks, overhead, mixed):
    """``CostModel.frame_ms`` of the frame drawn as ``picks`` (indices into the table's rows)."""
    used = np.zeros(table.shape[0], np.bool_)
    total = 0.0
    for i in range(len(picks)):
        total += table[picks[i], i]
        used[picks[i]] = True
    n_used = 0
    for s in range(table.shape[0]):
        if used[s]:
            total += overhead[s]
            n_used += 1
    return total + (mixed if n_used > 1 else 0.0)


@njit(cache=True)
def slab_cells_loop(lo, hi, spacing, eye, n):
    """``hybrid.cost.features.slab_cells_batch``: (B,) cells from (B, 3) box corners and (B, 2) spacings (metres)."""
    b = lo.shape[0]
    out = np.empty(b)
    diag = n * np.sqrt(2.0)
    for i in range(b):
        dz = hi[i, 2] - lo[i, 2]
        along = np.hypot(
            (0.5 * (lo[i, 0] + hi[i, 0]) - eye[0]) / spacing[i, 0],
            (0.5 * (lo[i, 1] + hi[i, 1]) - eye[1]) / spacing[i, 1],
        )
        height = abs(0.5 * (lo[i, 2] + hi[i, 2]) - eye[2])
        if dz == 0.0:
            out[i] = 0.0  # flat: none
        elif along == 0.0:
            out[i] = 1.0  # eye straight above
        elif height == 0.0:
            out[i] = diag  # level eye: the diagonal
        else:
            out[i] = min(dz * along / height, diag)
    return out


@njit(cache=True)
def with_mid_boxes(lo, hi):
    """(2B, 3) low and high corners: the B boxes (metres), then each flattened to its mid height (the surface's
    rough footprint), for one footprint call."""
    b = lo.shape[0]
    los, his = np.empty((2 * b, 3)), np.empty((2 * b, 3))
    for i in range(b):
        mid = 0.5 * (lo[i, 2] + hi[i, 2])
        for j in range(3):
            los[i, j], his[i, j] = lo[i, j], hi[i, j]
            los[b + i, j], his[b + i, j] = (lo[i, j], hi[i, j]) if j < 2 else (mid, mid)
    return los, his
