"""The ray caster following an edit: a resident tile's codes and max mipmap refreshed where the heights changed.

A tile's 16-bit codes (``hybrid.tiles.quantize``) keep their meaning while the tile's offset, step and base stay
the same: then only the codes of the changed samples are written and only the max-mip texels over them refilled
(``raycast.maxmip.texel_windows``). An edit that changes the tile's quantisation (its height range, or heights
leaving the source's step) changes every code, and the whole tile is written again into the same textures.
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from hybrid.terrain.edits import Window
from hybrid.tiles.quantize import quantize

from .gpu_tile import GpuTile
from .maxmip import MaxMipBuilder
from .tile_params import tile_row


def follow_tile(builder: MaxMipBuilder, gpu: GpuTile, tile, win: Window) -> bool:
    """Bring a resident tile up to date with ``tile`` (the pyramid's tile after the edit) whose samples changed
    over ``win`` (tile-local rows and columns, clipped to the tile), its max mipmap made by ``builder``; True when
    only the window was written."""
    qz = quantize(tile.heights, getattr(tile, "source_step", None))
    same = (qz.offset, qz.step, qz.base) == (gpu.offset, gpu.step, gpu.base)
    n, heights = gpu.n, cast(Any, gpu.heights)  # a moderngl texture
    if same and win.empty:
        pass  # none of the tile's own samples changed
    elif same:
        codes = np.ascontiguousarray(qz.q[win.slices()])
        heights.write(codes.tobytes(), viewport=(win.j0, win.i0, win.j1 - win.j0, win.i1 - win.i0))
        builder.update(gpu.heights, gpu.maxmip, n, win)
    else:
        heights.write(np.ascontiguousarray(qz.q).tobytes())
        builder.build(gpu.heights, n, out_tex=gpu.maxmip)
    gpu.offset, gpu.step, gpu.base, gpu.quant_error = qz.offset, qz.step, qz.base, qz.error
    gpu.row, gpu.bounds = tile_row(gpu, tile), (tile.clip, tile.zmin, tile.zmax)
    return same


def local_window(win: Window, key, n: int, rows: int, cols: int) -> Window:
    """The part of a window of level-0 samples inside tile ``key`` (n cells, level l), in the tile's own sample
    rows and columns: every level-l sample whose level-0 sample changed (a coarser tile samples every 2^l-th)."""
    k = 1 << key.level
    i0, j0 = key.ty * n * k, key.tx * n * k

    def axis(lo: int, hi: int, first: int, count: int) -> tuple[int, int]:
        a = max(-(-(lo - first) // k), 0)
        b = n + 1 if hi >= count else min((hi - 1 - first) // k + 1, n + 1)  # samples past the grid repeat its last
        return a, max(a, b)

    a0, a1 = axis(win.i0, win.i1, i0, rows)
    b0, b1 = axis(win.j0, win.j1, j0, cols)
    return Window(a0, a1, b0, b1)
