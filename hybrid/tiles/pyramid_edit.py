"""A tile pyramid following an edit of its height field: bounds, errors and caches of the touched tiles only.

After samples of a window of the level-0 grid change (``hybrid.terrain.edits.Window``), a tile's height bounds and
geometric error can change only where the tile's samples meet the window (its own cells' corners; a level-l tile's
error reads the level-0 samples it covers). ``update_pyramid`` recomputes exactly those tiles at every level with
the arithmetic of ``hybrid.tiles.bounds.level_bounds`` (maxima and minima are exact; each deviation is the same
operations on the same samples), so the arrays equal a full rebuild; the per-level caches made on first use (boxes,
selection tables, the dense selection's table, quantisation bounds, on-step flags) are updated over the same tiles.
"""

from __future__ import annotations

import weakref

import numpy as np

from hybrid.terrain.edits import Window
from hybrid.tiles.bounds import BLOCK_CELLS, _corner, _deviation, _reduce
from hybrid.tiles.pyramid import TileKey, TilePyramid
from hybrid.tiles.quantize import Q_MAX, error_bound, on_step_cells
from hybrid.tiles.tile_table import _TABLES


def touched_tiles(pyramid: TilePyramid, win: Window, level: int) -> tuple[range, range]:
    """(rows ty, columns tx) of the level's tiles whose samples meet a window of level-0 samples."""
    if win.empty:
        return range(0), range(0)
    b = pyramid.n << level
    rows, cols = pyramid.tile_counts(level)
    # a tile of b cells holds samples [t b, (t + 1) b]: borders belong to both neighbours
    r0, r1 = max((win.i0 - 1) // b, 0) if win.i0 > 0 else 0, min((win.i1 - 1) // b + 1, rows)
    c0, c1 = max((win.j0 - 1) // b, 0) if win.j0 > 0 else 0, min((win.j1 - 1) // b + 1, cols)
    return range(r0, r1), range(c0, c1)


def touched_keys(pyramid: TilePyramid, win: Window) -> list[TileKey]:
    """Every existing tile of every level whose samples meet the window, finest level first."""
    out = []
    for level in range(pyramid.max_level + 1):
        rows, cols = touched_tiles(pyramid, win, level)
        out += [TileKey(level, tx, ty) for ty in rows for tx in cols]
    return out


def _tile_cells(pyramid: TilePyramid, level: int, ty: int, tx: int) -> tuple[int, int, int, int]:
    """Cell rows [i0, i1) and columns [j0, j1) of level-0 cells a tile covers (clipped to the grid)."""
    hf, b = pyramid.hf, pyramid.n << level
    return ty * b, min((ty + 1) * b, hf.rows - 1), tx * b, min((tx + 1) * b, hf.cols - 1)


def _deviation_blocks(h: np.ndarray, k: int, a0: int, a1: int, b0: int, b1: int) -> np.ndarray:
    """Per block of k x k level-0 cells, rows [a0, a1) and columns [b0, b1) of blocks: the largest deviation
    (``level_bounds``' per-cell corner maximum) of the every-k-th-sample surface from the samples."""
    cells_r, cells_c = h.shape[0] - 1, h.shape[1] - 1
    i0, i1, j0, j1 = a0 * k, min(a1 * k, cells_r), b0 * k, min(b1 * k, cells_c)
    return _reduce(_corner(_deviation(h, k, i0, i1, j0, j1), np.maximum), k, np.maximum)


_BLOCKS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _level_blocks(pyramid: TilePyramid) -> dict:
    """Per level >= 1, the deviation maxima per block of 2^l x 2^l level-0 cells (made at the pyramid's first edit,
    one pass over the grid a level), so an edit re-measures only the blocks around it."""
    if pyramid not in _BLOCKS:
        h = pyramid.hf.heights
        cells_r, cells_c = h.shape[0] - 1, h.shape[1] - 1
        out = {}
        for level in range(1, pyramid.max_level + 1):
            k = 1 << level
            step, rows = max(1, BLOCK_CELLS // k), -(-cells_r // k)  # a band of blocks at once (memory bound)
            out[level] = np.concatenate(
                [_deviation_blocks(h, k, a, min(a + step, rows), 0, -(-cells_c // k)) for a in range(0, rows, step)]
            )
        _BLOCKS[pyramid] = out
    return _BLOCKS[pyramid]


def _bounds(pyramid: TilePyramid, win: Window) -> None:
    """Recompute zmax, zmin and err of the touched tiles of every level (level_bounds' values)."""
    blocks = _level_blocks(pyramid)
    h, zmax, zmin, err = pyramid.hf.heights, pyramid._zmax, pyramid._zmin, pyramid._err
    rows0, cols0 = touched_tiles(pyramid, win, 0)
    for ty in rows0:
        for tx in cols0:
            i0, i1, j0, j1 = _tile_cells(pyramid, 0, ty, tx)
            sub = h[i0 : i1 + 1, j0 : j1 + 1]
            zmax[0][ty, tx], zmin[0][ty, tx] = _corner(sub, np.maximum).max(), _corner(sub, np.minimum).min()
    for level in range(1, pyramid.max_level + 1):
        k, dev = 1 << level, blocks[level]
        # a block's cells read samples of its own coarse cell and the next one's first row: two blocks of margin
        a0, a1 = max(win.i0 // k - 2, 0), min((win.i1 - 1) // k + 2, dev.shape[0])
        b0, b1 = max(win.j0 // k - 2, 0), min((win.j1 - 1) // k + 2, dev.shape[1])
        dev[a0:a1, b0:b1] = _deviation_blocks(h, k, a0, a1, b0, b1)
        rows, cols = touched_tiles(pyramid, win, level)
        n = pyramid.n
        for ty in rows:
            for tx in cols:
                kids = (slice(ty * k, (ty + 1) * k), slice(tx * k, (tx + 1) * k))
                zmax[level][ty, tx], zmin[level][ty, tx] = zmax[0][kids].max(), zmin[0][kids].min()
                mine = dev[ty * n : (ty + 1) * n, tx * n : (tx + 1) * n].max()
                below = err[level - 1][2 * ty : 2 * ty + 2, 2 * tx : 2 * tx + 2].max()
                err[level][ty, tx] = max(mine, below)


def _on_step(pyramid: TilePyramid, win: Window) -> None:
    """The per-cell on-step flags over the cells whose corners the window holds."""
    h = pyramid.hf.heights
    i0, j0 = max(win.i0 - 1, 0), max(win.j0 - 1, 0)
    cells = on_step_cells(h[i0 : min(win.i1 + 1, h.shape[0]), j0 : min(win.j1 + 1, h.shape[1])], pyramid.hf.source_step)
    if cells is None or pyramid._on_step is None:
        return
    pyramid._on_step[i0 : i0 + cells.shape[0], j0 : j0 + cells.shape[1]] = cells


def _qerr(pyramid: TilePyramid, level: int, ty: int, tx: int) -> float:
    """One tile's quantisation bound, as ``TilePyramid.quantization_errors_at`` computes every tile's."""
    lo, hi = pyramid._zmin[level][ty, tx], pyramid._zmax[level][ty, tx]
    exact = False
    step = pyramid.hf.source_step
    if step is not None and pyramid._on_step is not None:
        i0, i1, j0, j1 = _tile_cells(pyramid, level, ty, tx)
        exact = bool(pyramid._on_step[i0:i1, j0:j1].all()) and (float(hi) - float(lo)) / float(step[0]) <= Q_MAX - 0.5
    return float(error_bound(lo, hi, exact))


def _caches(pyramid: TilePyramid, win: Window) -> None:
    """Bring the per-level caches made on first use up to date over the touched tiles."""
    if pyramid._on_step is not None:
        _on_step(pyramid, win)
    for level in range(pyramid.max_level + 1):
        rows, cols = touched_tiles(pyramid, win, level)
        keys = [(ty, tx) for ty in rows for tx in cols]
        if not keys:
            continue
        ty, tx = (np.array(a, dtype=np.int64) for a in zip(*keys, strict=True))
        if level in pyramid._qerr:
            q = pyramid._qerr[level]
            q[ty, tx] = [_qerr(pyramid, level, a, b) for a, b in keys]
        if level in pyramid._boxes:
            lo, hi = pyramid.aabbs(np.full(ty.size, level), tx, ty)
            pyramid._boxes[level][0][ty, tx], pyramid._boxes[level][1][ty, tx] = lo, hi
        if level in pyramid._tables or pyramid in _TABLES:
            lo, hi = pyramid.boxes_at(level, tx, ty)
            e = pyramid.errors_at(level, tx, ty) + pyramid.quantization_errors_at(level, tx, ty)
            rows7 = np.concatenate([lo, hi, e[:, None]], axis=1)
            if level in pyramid._tables:
                pyramid._tables[level][ty, tx] = rows7
            if pyramid in _TABLES:  # the dense selection's flat table of tile places
                side = pyramid.tiles_per_side(level)
                first = sum(pyramid.tiles_per_side(lv) ** 2 for lv in range(level))
                _TABLES[pyramid].boxes[first + ty * side + tx] = rows7


def update_pyramid(pyramid: TilePyramid, win: Window) -> list[TileKey]:
    """Bring a pyramid up to date after the samples of ``win`` changed in its height field: bounds, errors and
    caches of the touched tiles; returns those tiles (``touched_keys``)."""
    if win.empty:
        return []
    pyramid.hf._range = (None, None)  # the height range is read again
    _bounds(pyramid, win)
    _caches(pyramid, win)
    return touched_keys(pyramid, win)
