"""The arithmetic of a tile pyramid following an edit of its height field: bounds, errors and caches of the
touched tiles only (``TilePyramid.follow_edit`` runs it over its own arrays).

After samples of a window of the level-0 grid change (``hybrid.terrain.edits.Window``), a tile's height bounds and
geometric error can change only where the tile's samples meet the window (its own cells' corners; a level-l tile's
error reads the level-0 samples it covers). ``edit_bounds`` recomputes exactly those tiles at every level with
the arithmetic of ``hybrid.tiles.bounds.level_bounds`` (maxima and minima are exact; each deviation is the same
operations on the same samples), so the arrays equal a full rebuild; ``follow_caches`` updates the per-level caches
made on first use (boxes, selection tables, quantisation bounds, on-step flags) over the same tiles.

This module sits below ``hybrid.tiles.pyramid`` (which imports it), so it names the pyramid only by what it reads:
its tile size ``n``, ``tile_counts``, ``hf`` and the public per-tile look-ups.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hybrid.terrain.edits import Window
from hybrid.tiles.bounds import BLOCK_CELLS, _reduce
from hybrid.tiles.quantize import _HALF_ULP, Q_MAX, on_step_cells

Touched = list[tuple[range, range]]
"""Per level, (rows ty, columns tx) of the tiles an edit touched (``touched_tiles``)."""


def touched_tiles(pyramid: Any, win: Window, level: int) -> tuple[range, range]:
    """(rows ty, columns tx) of the level's tiles whose samples meet a window of level-0 samples."""
    if win.empty:
        return range(0), range(0)
    b = pyramid.n << level
    rows, cols = pyramid.tile_counts(level)
    # a tile of b cells holds samples [t b, (t + 1) b]: borders belong to both neighbours
    r0, r1 = max((win.i0 - 1) // b, 0) if win.i0 > 0 else 0, min((win.i1 - 1) // b + 1, rows)
    c0, c1 = max((win.j0 - 1) // b, 0) if win.j0 > 0 else 0, min((win.j1 - 1) // b + 1, cols)
    return range(r0, r1), range(c0, c1)


def _tile_cells(h: np.ndarray, n: int, level: int, ty: int, tx: int) -> tuple[int, int, int, int]:
    """Cell rows [i0, i1) and columns [j0, j1) of level-0 cells a tile covers (clipped to the grid)."""
    b = n << level
    return ty * b, min((ty + 1) * b, h.shape[0] - 1), tx * b, min((tx + 1) * b, h.shape[1] - 1)


def _deviation_blocks(h: np.ndarray, k: int, a0: int, a1: int, b0: int, b1: int) -> np.ndarray:
    """Per block of k x k level-0 cells, rows [a0, a1) and columns [b0, b1) of blocks: the largest deviation
    (``level_bounds``' per-cell corner maximum) of the every-k-th-sample surface from the samples."""
    from .bounds_loops import deviation_block_max

    return deviation_block_max(h, k, a0, a1, b0, b1)


SUPER = 16
"""Deviation blocks a side of a super-block: a tile's error after an edit reads its super-blocks' maxima."""


@dataclass
class DeviationBlocks:
    """Per level >= 1, the deviation maxima per block of 2^l x 2^l level-0 cells (``dev``) and their maxima per
    ``s`` x ``s`` blocks (``sup``, s dividing the tile size), so that an edit re-measures only the blocks around it
    and a touched tile's error reads (n / s)² super-blocks rather than n² blocks."""

    dev: dict[int, np.ndarray]
    sup: dict[int, np.ndarray]
    s: int


def level_blocks(h: np.ndarray, max_level: int, n: int) -> DeviationBlocks:
    """The ``DeviationBlocks`` of a grid for tiles of n cells (one pass over the grid a level, at a pyramid's first
    edit)."""
    cells_r, cells_c = h.shape[0] - 1, h.shape[1] - 1
    dev, sup, s = {}, {}, min(SUPER, n)
    for level in range(1, max_level + 1):
        k = 1 << level
        step, rows = max(1, BLOCK_CELLS // k), -(-cells_r // k)  # a band of blocks at once (memory bound)
        dev[level] = np.concatenate(
            [_deviation_blocks(h, k, a, min(a + step, rows), 0, -(-cells_c // k)) for a in range(0, rows, step)]
        )
        sup[level] = _reduce(dev[level], s, np.maximum)
    return DeviationBlocks(dev, sup, s)


@dataclass
class LevelArrays:
    """A pyramid's per-level arrays an edit rewrites: (tile rows, tile columns) float32 per level."""

    zmax: dict[int, np.ndarray]
    zmin: dict[int, np.ndarray]
    err: dict[int, np.ndarray]


def edit_bounds(h: np.ndarray, n: int, a: LevelArrays, blocks: DeviationBlocks, win: Window, touched: Touched) -> None:
    """Recompute zmax, zmin and err of the touched tiles of every level (``level_bounds``' values) in place,
    and the deviation ``blocks`` (``level_blocks``) around the window."""
    rows0, cols0 = touched[0]
    for ty in rows0:
        for tx in cols0:
            i0, i1, j0, j1 = _tile_cells(h, n, 0, ty, tx)
            sub = h[i0 : i1 + 1, j0 : j1 + 1]
            a.zmax[0][ty, tx], a.zmin[0][ty, tx] = sub.max(), sub.min()  # every sample is some cell's corner
    from .pyramid_edit_loops import follow_level_bounds

    w = np.array([win.i0, win.i1, win.j0, win.j1], dtype=np.int64)
    for level in range(1, len(touched)):
        rows, cols = touched[level]
        tiles = np.array([rows.start, rows.stop, cols.start, cols.stop], dtype=np.int64)
        follow_level_bounds(
            h,
            1 << level,
            w,
            blocks.dev[level],
            blocks.sup[level],
            blocks.s,
            tiles,
            a.zmax[0],
            a.zmin[0],
            a.zmax[level],
            a.zmin[level],
            a.err[level],
            a.err[level - 1],
            n // blocks.s,
        )


def follow_on_step(on_step: np.ndarray, h: np.ndarray, step, win: Window) -> None:
    """The per-cell on-step flags over the cells whose corners the window holds, in place."""
    grown = win.grown(1, *h.shape)
    cells = on_step_cells(h[grown.slices()], step)
    if cells is not None:
        on_step[grown.i0 : grown.i0 + cells.shape[0], grown.j0 : grown.j0 + cells.shape[1]] = cells


def follow_on_tiles(on_tiles: dict, h: np.ndarray, n: int, on_step, touched: Touched) -> None:
    """The per-level on-step flags of the touched tiles (``TilePyramid._on_step_tiles``), finest level first, in
    place: a level-0 tile from its cells, a coarser one from its children where their level is kept (an AND of
    at most four flags, not of every cell it covers)."""
    for level, (rows, cols) in enumerate(touched):
        flags = on_tiles.get(level)
        if flags is None or on_step is None:
            continue
        below = on_tiles.get(level - 1)
        for ty in rows:
            for tx in cols:
                if below is None:
                    i0, i1, j0, j1 = _tile_cells(h, n, level, ty, tx)
                    flags[ty, tx] = on_step[i0:i1, j0:j1].all()
                else:
                    flags[ty, tx] = below[2 * ty : 2 * ty + 2, 2 * tx : 2 * tx + 2].all()


def follow_caches(pyramid: Any, caches: dict[str, Any], win: Window, touched: Touched) -> None:
    """Bring the pyramid's per-level caches made on first use up to date over the touched tiles, in place
    (``caches``: its ``qerr``, ``boxes`` and ``tables`` per level and its ``on_step`` flags, or None)."""
    h, n, step, on_step = pyramid.hf.heights, pyramid.n, getattr(pyramid.hf, "source_step", None), caches["on_step"]
    if on_step is not None:
        follow_on_step(on_step, h, step, win)
    on_tiles = caches["on_tiles"]
    follow_on_tiles(on_tiles, h, n, on_step, touched)
    from .pyramid_edit_loops import follow_level_caches

    hf = pyramid.hf
    ox, oy, oz = (float(v) for v in hf.origin)
    x_end, y_end = ox + (hf.cols - 1) * hf.spacing_x, oy + (hf.rows - 1) * hf.spacing_y
    q = np.array([float(Q_MAX), _HALF_ULP])
    none = np.zeros((0, 0))
    for level, (rows, cols) in enumerate(touched):
        if not (len(rows) and len(cols)):
            continue
        tables = caches["tables"].get(level)
        if tables is not None:  # the table reads the level's boxes and bounds: made whole where not yet
            pyramid.boxes_at(level, np.zeros(1, np.int64), np.zeros(1, np.int64))
            pyramid.quantization_errors_at(level, np.zeros(1, np.int64), np.zeros(1, np.int64))
        boxes = caches["boxes"].get(level)
        zmin, zmax, err = pyramid.level_arrays(level)
        on = on_tiles.get(level)
        cells = pyramid.n << level
        geo = np.array([ox, oy, oz, cells * hf.spacing_x, cells * hf.spacing_y, x_end, y_end])
        follow_level_caches(
            np.array([rows.start, rows.stop, cols.start, cols.stop], dtype=np.int64),
            geo,
            zmin,
            zmax,
            err,
            np.zeros((0, 0), np.bool_) if on is None else on,
            float(step[0]) if step is not None else -1.0,
            q,
            caches["qerr"].get(level, none),
            none.reshape(0, 0, 3) if boxes is None else boxes[0],
            none.reshape(0, 0, 3) if boxes is None else boxes[1],
            none.reshape(0, 0, 7) if tables is None else tables,
        )
