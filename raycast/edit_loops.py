"""A resident tile's 16-bit codes and max mipmap kept on the host after its first edit, and brought up to date over
an edit's window, compiled by numba.

``hybrid.tiles.quantize.quantize`` chooses a tile's quantisation from its whole range and whether every sample is
on the source's step. Both follow from per-row summaries (lowest, highest, samples off the step), so an edit
re-reads only the rows it touched to learn whether the quantisation stays. Where it does, only the window's codes
change, the largest error is the maximum of per-row errors (whole rows re-measured), and only the max-mip texels
over the window (``raycast.maxmip.texel_windows``) are made again. The arithmetic is ``quantize``'s and
``code_mip_levels``' own, so the codes, error and levels equal a whole-tile rebuild bit for bit. Imported where
first called, so that a process that never edits does not load numba."""

from __future__ import annotations

import numpy as np
from numba import njit

from hybrid.tiles.quantize_loops import range_code, range_error, step_of

from .mip_loops import code_mip_levels

STEP, RANGE, FLAT = 0, 1, 2  # the three quantisations of ``quantize``


@njit(cache=True)
def row_summaries(h, r0, r1, src, lo, hi, off):
    """Rows [r0, r1) of float32 heights h: their lowest and highest (float64) and samples off the source step
    ``src`` (step, offset; step <= 0: none), into lo, hi, off in place."""
    for i in range(r0, r1):
        a, b, o = np.inf, -np.inf, 0.0
        for j in range(h.shape[1]):
            v = np.float64(h[i, j])
            a, b = min(a, v), max(b, v)
            if src[0] > 0.0 and not step_of(h[i, j], src[0], src[1])[1]:
                o += 1.0
        lo[i], hi[i], off[i] = a, b, o


@njit(cache=True)
def choose(lo, hi, off, src, q_max):
    """``quantize``'s choice from the row summaries: (kind, offset, step, base)."""
    a, b = lo.min(), hi.max()
    if src[0] > 0.0 and off.sum() == 0.0:
        kmin, kmax = np.rint((a - src[1]) / src[0]), np.rint((b - src[1]) / src[0])
        if kmax - kmin <= q_max and abs(kmin) < 2.0**31:
            return STEP, src[1], src[0], np.int64(kmin)
    if b == a:
        return FLAT, a, 1.0, np.int64(0)
    return RANGE, a, (b - a) / q_max, np.int64(0)


@njit(cache=True)
def write_codes(h, q, i0, i1, j0, j1, kind, offset, step, base, q_max):
    """Codes of samples [i0, i1) x [j0, j1) of h into q, by the quantisation (kind, offset, step, base)."""
    for i in range(i0, i1):
        for j in range(j0, j1):
            v = np.float64(h[i, j])
            if kind == STEP:
                q[i, j] = np.uint16(step_of(h[i, j], step, offset)[0] - base)
            elif kind == RANGE:
                q[i, j] = np.uint16(range_code(v, offset, step, q_max))
            else:
                q[i, j] = 0


@njit(cache=True)
def row_errors(h, q, r0, r1, offset, step, err):
    """Largest |height - float32(offset + step * code)| of each row [r0, r1) of a range-coded tile, into err."""
    for i in range(r0, r1):
        e = 0.0
        for j in range(h.shape[1]):
            e = max(e, range_error(np.float64(h[i, j]), offset, step, q[i, j]))
        err[i] = e


@njit(cache=True)
def update_mips(q, flat, wins):
    """Max-mip levels 1..log2 N (``code_mip_levels``' flat array) of codes q over each level's texel window
    ``wins[k]`` (r0, r1, c0, c1) only, in place (``code_mip_levels``' arithmetic, which is faster over a whole
    tile); returns how many levels, from level 1, changed: a level whose window kept every value leaves the
    coarser ones as they were, and they are not visited."""
    m, start = (q.shape[0] - 1) // 2, 0
    r0, r1, c0, c1 = wins[0]
    changed = False
    for r in range(r0, r1):
        for c in range(c0, c1):
            best = q[2 * r, 2 * c]
            for i in range(2 * r, 2 * r + 3):
                for j in range(2 * c, 2 * c + 3):
                    best = max(best, q[i, j])
            changed |= flat[r * m + c] != best
            flat[r * m + c] = best
    for k in range(1, wins.shape[0]):
        if not changed:
            return k
        half, nxt = m // 2, start + m * m
        r0, r1, c0, c1 = wins[k]
        changed = False
        for r in range(r0, r1):
            for c in range(c0, c1):
                a = start + 2 * r * m + 2 * c
                v = max(flat[a], flat[a + 1], flat[a + m], flat[a + m + 1])
                changed |= flat[nxt + r * half + c] != v
                flat[nxt + r * half + c] = v
        start, m = nxt, half
    return wins.shape[0] if changed else wins.shape[0] - 1


@njit(cache=True)
def follow_codes(h, q, flat, sums, err, params, win, wins, src, whole, q_max):
    """Bring a tile's host codes q, max-mip levels ``flat``, row summaries ``sums`` (3, N+1: lowest, highest,
    samples off the step) and row errors ``err`` up to date after samples ``win`` (i0, i1, j0, j1) of its heights
    h changed, in place; ``whole`` re-makes everything (no host state yet). ``params`` (offset, step, base, kind;
    kind < 0: not known) is the quantisation the codes had and becomes the new one. Returns (largest error,
    same, levels): same where the quantisation stayed, so that the codes changed over the window only, and then
    the max-mip levels whose window changed (``update_mips``)."""
    i0, i1, j0, j1 = win
    rows = q.shape[0]
    r0, r1 = (0, rows) if whole else (i0, i1)
    row_summaries(h, r0, r1, src, sums[0], sums[1], sums[2])
    kind, offset, step, base = choose(sums[0], sums[1], sums[2], src, q_max)
    same = offset == params[0] and step == params[1] and base == params[2] and (params[3] < 0 or kind == params[3])
    params[0], params[1], params[2], params[3] = offset, step, base, kind
    if whole or not same:
        r0, r1 = 0, rows
        write_codes(h, q, 0, rows, 0, rows, kind, offset, step, base, q_max)
        flat[:] = code_mip_levels(q)  # a fresh array, which the compiler vectorises: several times update_mips'
        levels = wins.shape[0]
    else:
        write_codes(h, q, i0, i1, j0, j1, kind, offset, step, base, q_max)
        levels = update_mips(q, flat, wins)
    error = 0.0
    if kind == RANGE:
        row_errors(h, q, r0, r1, offset, step, err)
        error = err.max()
    return error, same, levels
