"""The arithmetic of a tile pyramid following an edit of its height field: bounds, errors and caches of the
touched tiles only (``TilePyramid.follow_edit`` runs it over its own arrays).

After samples of a window of the level-0 grid change (``hybrid.terrain.edits.Window``), a tile's height bounds and
geometric error can change only where the tile's samples meet the window (its own cells' corners; a level-l tile's
error reads the level-0 samples it covers). ``follow_levels`` recomputes exactly those tiles at every level with
the arithmetic of ``hybrid.tiles.bounds.level_bounds`` (maxima and minima are exact; each deviation is the same
operations on the same samples), so the arrays equal a full rebuild, and updates the per-level caches made on
first use (boxes, selection tables, quantisation bounds, on-step flags) over the same tiles: one compiled call
for every level, since a call a level cost more in its Python and numpy glue than in arithmetic.

This module sits below ``hybrid.tiles.pyramid`` (which imports it), so it names the pyramid only by what it reads:
its tile size ``n``, ``tile_counts``, ``hf`` and the public per-tile look-ups.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hybrid.terrain.edits import Window
from hybrid.tiles.bounds import BLOCK_CELLS, _reduce
from hybrid.tiles.quantize import _HALF_ULP, Q_MAX


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
    and a touched tile's error reads (n / s)² super-blocks rather than n² blocks; and the highest and lowest
    sample of each s x s block of level-0 cells, borders included (``zhi``, ``zlo``), from which a touched level-0
    tile's bounds are read."""

    dev: dict[int, np.ndarray]
    sup: dict[int, np.ndarray]
    s: int
    zhi: np.ndarray
    zlo: np.ndarray


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
    from .pyramid_edit_loops import sample_block_bounds

    zhi = np.empty((-(-cells_r // s), -(-cells_c // s)), h.dtype)
    zlo = np.empty_like(zhi)
    sample_block_bounds(h, s, 0, zhi.shape[0], 0, zhi.shape[1], zhi, zlo)
    return DeviationBlocks(dev, sup, s, zhi, zlo)


@dataclass
class LevelArrays:
    """A pyramid's per-level arrays an edit rewrites: (tile rows, tile columns) float32 per level."""

    zmax: dict[int, np.ndarray]
    zmin: dict[int, np.ndarray]
    err: dict[int, np.ndarray]


def follow_levels(pyramid: Any, a: LevelArrays, caches: dict[str, Any], blocks: DeviationBlocks, win: Window) -> None:
    """Recompute zmax, zmin and err of the touched tiles of every level (``level_bounds``' values), the deviation
    ``blocks`` around the window, the on-step flags and the per-level caches made on first use (``caches``: its
    ``qerr``, ``boxes``, ``tables`` and ``on_tiles`` per level and its ``on_step`` flags, or None) over the
    touched tiles, in place, in one compiled call (``pyramid_edit_loops.follow_pyramid``)."""
    from .pyramid_edit_loops import follow_pyramid

    hf, n, levels = pyramid.hf, pyramid.n, range(len(a.zmax))
    h, step, on_step = hf.heights, getattr(hf, "source_step", None), caches["on_step"]
    for level in levels:
        if level in caches["tables"]:  # the table reads the level's boxes and bounds: made whole where not yet
            pyramid.boxes_at(level, np.zeros(1, np.int64), np.zeros(1, np.int64))
            pyramid.quantization_errors_at(level, np.zeros(1, np.int64), np.zeros(1, np.int64))
    touched = [touched_tiles(pyramid, win, level) for level in levels]
    tiles = np.array([[r.start, r.stop, c.start, c.stop] for r, c in touched], dtype=np.int64)
    f2, f3, b2 = np.zeros((0, 0)), np.zeros((0, 0, 3)), np.zeros((0, 0), np.bool_)
    bounds = tuple(tuple(d[level] for level in levels) for d in (a.zmax, a.zmin, a.err))
    dev = tuple((blocks.dev if level else {}).get(level, f2) for level in levels)
    sup = tuple((blocks.sup if level else {}).get(level, f2) for level in levels)
    boxes = caches["boxes"]
    made = (
        tuple(caches["qerr"].get(level, f2) for level in levels),
        tuple(boxes[level][0] if level in boxes else f3 for level in levels),
        tuple(boxes[level][1] if level in boxes else f3 for level in levels),
        tuple(caches["tables"].get(level, np.zeros((0, 0, 7))) for level in levels),
    )
    on_tiles = tuple(caches["on_tiles"].get(level, b2) for level in levels)
    ox, oy, oz = (float(v) for v in hf.origin)
    x_end, y_end = ox + (hf.cols - 1) * hf.spacing_x, oy + (hf.rows - 1) * hf.spacing_y
    geo = np.array([ox, oy, oz, n * hf.spacing_x, n * hf.spacing_y, x_end, y_end])
    g = win.grown(1, *h.shape)
    follow_pyramid(
        h,
        n,
        np.array([win.i0, win.i1, win.j0, win.j1], dtype=np.int64),
        tiles,
        bounds,
        (dev, sup),
        blocks.s,
        (blocks.zhi, blocks.zlo),
        b2 if on_step is None or step is None else on_step,
        np.array([g.i0, g.i1, g.j0, g.j1], dtype=np.int64),
        np.array(step if step is not None else (-1.0, 0.0), dtype=np.float64),
        on_tiles,
        made,
        geo,
        np.array([float(Q_MAX), _HALF_ULP]),
    )
