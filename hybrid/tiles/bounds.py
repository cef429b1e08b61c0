"""A pyramid's per-tile height bounds and geometric errors, computed block by block over the level-0 grid.

Every value equals what the whole-grid computation gives (maxima and minima are exact, and each sample's
interpolated height is the same arithmetic on the same samples), but the work arrays cover one block of
BLOCK_CELLS² cells at a time, so the peak memory is the heights plus a few MiB, at any grid size.
"""

from __future__ import annotations

import numpy as np

BLOCK_CELLS = 512
"""Cells a side of a block: its float64 work arrays take 2 MiB each."""


def _reduce(a: np.ndarray, b: int, fn) -> np.ndarray:
    """Reduce a 2-D array over b x b blocks with the ufunc fn, partial blocks at the ends."""
    rows, cols = np.arange(0, a.shape[0], b), np.arange(0, a.shape[1], b)
    return fn.reduceat(fn.reduceat(a, rows, axis=0), cols, axis=1)


def _blocks(cells_r: int, cells_c: int):
    """(i0, i1, j0, j1) cell ranges of the blocks covering a cells_r x cells_c grid of cells."""
    c = BLOCK_CELLS
    for i0 in range(0, cells_r, c):
        for j0 in range(0, cells_c, c):
            yield i0, min(i0 + c, cells_r), j0, min(j0 + c, cells_c)


def _fold(out: np.ndarray, cells: np.ndarray, i0: int, j0: int, b: int, fn) -> None:
    """Fold a block of per-cell values starting at cell (i0, j0) into ``out``'s tiles of b cells with fn."""
    part = _reduce(cells, min(b, BLOCK_CELLS), fn)
    r, c = i0 // b, j0 // b
    view = out[r : r + part.shape[0], c : c + part.shape[1]]
    view[...] = fn(view, part)


def _corner(a: np.ndarray, fn) -> np.ndarray:
    """Per cell of a sample grid: fn over its four corner samples."""
    return fn(fn(a[:-1, :-1], a[:-1, 1:]), fn(a[1:, :-1], a[1:, 1:]))


def _axis(lo: int, hi: int, n: int, k: int):
    """Coarse sample indices (clamped to n - 1) and fractions of samples lo..hi-1 on every k-th sample."""
    idx = np.arange(lo, hi)
    c = idx // k
    return np.minimum(c * k, n - 1), np.minimum((c + 1) * k, n - 1), (idx - c * k) / k


def _deviation(h: np.ndarray, k: int, i0: int, i1: int, j0: int, j1: int) -> np.ndarray:
    """|triangulated every-k-th-sample surface - h| at samples [i0, i1] x [j0, j1] (float64)."""
    r0, r1, fi = _axis(i0, i1 + 1, h.shape[0], k)
    c0, c1, fj = _axis(j0, j1 + 1, h.shape[1], k)
    fi, fj = fi[:, None], fj[None, :]
    h00, h01 = h[np.ix_(r0, c0)].astype(np.float64), h[np.ix_(r0, c1)].astype(np.float64)
    h10, h11 = h[np.ix_(r1, c0)].astype(np.float64), h[np.ix_(r1, c1)].astype(np.float64)
    lower = h00 + fj * (h01 - h00) + fi * (h11 - h01)
    upper = h00 + fi * (h10 - h00) + fj * (h11 - h10)
    surface = np.where(fj >= fi, lower, upper)
    return np.abs(surface - h[i0 : i1 + 1, j0 : j1 + 1].astype(np.float64))


def level_bounds(h: np.ndarray, n: int, max_level: int) -> tuple[dict, dict, dict]:
    """Per level 0..max_level: tiles' (zmax, zmin, err) arrays for tiles of n cells over heights h."""
    cells_r, cells_c = h.shape[0] - 1, h.shape[1] - 1
    shape0 = (-(-cells_r // n), -(-cells_c // n))
    zmax0, zmin0 = np.full(shape0, -np.inf, h.dtype), np.full(shape0, np.inf, h.dtype)
    for i0, i1, j0, j1 in _blocks(cells_r, cells_c):
        sub = h[i0 : i1 + 1, j0 : j1 + 1]
        _fold(zmax0, _corner(sub, np.maximum), i0, j0, n, np.maximum)
        _fold(zmin0, _corner(sub, np.minimum), i0, j0, n, np.minimum)
    zmax, zmin, err = {0: zmax0}, {0: zmin0}, {0: np.zeros(shape0)}
    for level in range(1, max_level + 1):
        k = 1 << level
        zmax[level], zmin[level] = _reduce(zmax0, k, np.maximum), _reduce(zmin0, k, np.minimum)
        e = np.zeros(zmax[level].shape)
        for i0, i1, j0, j1 in _blocks(cells_r, cells_c):
            _fold(e, _corner(_deviation(h, k, i0, i1, j0, j1), np.maximum), i0, j0, n * k, np.maximum)
        err[level] = np.maximum(e, _reduce(err[level - 1], 2, np.maximum))
    return zmax, zmin, err


def strided_samples(h: np.ndarray, i0: int, j0: int, k: int, m: int) -> np.ndarray:
    """(m, m) samples of grid ``h`` every k-th from (row i0, column j0), indices past the grid clamped to its last
    row or column (strided slices, no index arrays)."""
    rows, cols = h.shape
    cr, cc = min(m, (rows - 1 - i0) // k + 1), min(m, (cols - 1 - j0) // k + 1)  # samples inside the grid
    r, c = slice(i0, i0 + (cr - 1) * k + 1, k), slice(j0, j0 + (cc - 1) * k + 1, k)
    out = np.empty((m, m), h.dtype)
    out[:cr, :cc] = h[r, c]
    out[:cr, cc:] = h[r, cols - 1][:, None]
    out[cr:, :cc] = h[rows - 1, c]
    out[cr:, cc:] = h[rows - 1, cols - 1]
    return out
