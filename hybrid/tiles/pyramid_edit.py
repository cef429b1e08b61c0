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
from hybrid.tiles.quantize import Q_MAX, error_bound, on_step_cells

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
    for level in range(1, len(touched)):
        k, dev, sup, s = 1 << level, blocks.dev[level], blocks.sup[level], blocks.s
        # block a depends on samples [a k, (a + 1) k] only (its last sample's surface gives the next coarse
        # cell's far corner weight 0): the blocks whose closed range meets the window
        a0, a1 = max((win.i0 - 1) // k, 0), min((win.i1 - 1) // k + 1, dev.shape[0])
        b0, b1 = max((win.j0 - 1) // k, 0), min((win.j1 - 1) // k + 1, dev.shape[1])
        dev[a0:a1, b0:b1] = _deviation_blocks(h, k, a0, a1, b0, b1)
        r0, r1, c0, c1 = a0 // s, -(-a1 // s), b0 // s, -(-b1 // s)
        sup[r0:r1, c0:c1] = _reduce(dev[r0 * s : r1 * s, c0 * s : c1 * s], s, np.maximum)
        m = n // s  # super-blocks a tile side
        rows, cols = touched[level]
        for ty in rows:
            for tx in cols:
                kids = (slice(ty * k, (ty + 1) * k), slice(tx * k, (tx + 1) * k))
                a.zmax[level][ty, tx], a.zmin[level][ty, tx] = a.zmax[0][kids].max(), a.zmin[0][kids].min()
                mine = sup[ty * m : (ty + 1) * m, tx * m : (tx + 1) * m].max()
                below = a.err[level - 1][2 * ty : 2 * ty + 2, 2 * tx : 2 * tx + 2].max()
                a.err[level][ty, tx] = max(mine, below)


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


def tile_qerr(lo: float, hi: float, step, on_tile: bool) -> float:
    """One tile's quantisation bound (lo, hi its bounds in metres; ``on_tile``: every cell it covers on the source
    step), as ``TilePyramid.quantization_errors_at`` computes every tile's."""
    exact = step is not None and on_tile and (float(hi) - float(lo)) / float(step[0]) <= Q_MAX - 0.5
    return float(error_bound(lo, hi, exact))


def follow_caches(pyramid: Any, caches: dict[str, Any], win: Window, touched: Touched) -> None:
    """Bring the pyramid's per-level caches made on first use up to date over the touched tiles, in place
    (``caches``: its ``qerr``, ``boxes`` and ``tables`` per level and its ``on_step`` flags, or None)."""
    h, n, step, on_step = pyramid.hf.heights, pyramid.n, getattr(pyramid.hf, "source_step", None), caches["on_step"]
    if on_step is not None:
        follow_on_step(on_step, h, step, win)
    on_tiles = caches["on_tiles"]
    follow_on_tiles(on_tiles, h, n, on_step, touched)
    for level, (rows, cols) in enumerate(touched):
        keys = [(ty, tx) for ty in rows for tx in cols]
        if not keys:
            continue
        ty, tx = (np.array(a, dtype=np.int64) for a in zip(*keys, strict=True))
        if level in caches["qerr"]:
            zmin, zmax, _ = pyramid.level_arrays(level)
            on = on_tiles.get(level)
            caches["qerr"][level][ty, tx] = [
                tile_qerr(zmin[a, b], zmax[a, b], step, on is not None and bool(on[a, b])) for a, b in keys
            ]
        if level in caches["boxes"]:
            lo, hi = pyramid.aabbs(np.full(ty.size, level), tx, ty)
            caches["boxes"][level][0][ty, tx], caches["boxes"][level][1][ty, tx] = lo, hi
        if level in caches["tables"]:
            lo, hi = pyramid.boxes_at(level, tx, ty)
            e = pyramid.errors_at(level, tx, ty) + pyramid.quantization_errors_at(level, tx, ty)
            caches["tables"][level][ty, tx] = np.concatenate([lo, hi, e[:, None]], axis=1)
