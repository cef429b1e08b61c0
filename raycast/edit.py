"""The ray caster following an edit: a resident tile's codes and max mipmap refreshed where the heights changed.

A tile's 16-bit codes (``hybrid.tiles.quantize``) keep their meaning while the tile's offset, step and base stay
the same: then only the codes of the changed samples are written and only the max-mip texels over them
(``raycast.maxmip.texel_windows``). An edit that changes the tile's quantisation (its height range, or heights
leaving the source's step) changes every code, and the whole tile is written again into the same textures. The
max mipmap is made on the host from the codes, as a tile's upload makes it (``raycast.gpu_tile.code_mips``), and
written level by level: a texture write a level, where building it on the GPU took a dispatch and a barrier a
level (on a CPU rasterizer each of those costs as much as the whole write).
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from hybrid.gl.context import write_red_level
from hybrid.terrain.edits import Window
from hybrid.tiles.quantize import quantize

from .gpu_tile import GpuTile, code_mips, metres_as_codes
from .maxmip import texel_windows
from .tile_params import tile_row


def follow_tile(gpu: GpuTile, tile, win: Window) -> bool:
    """Bring a resident tile up to date with ``tile`` (the pyramid's tile after the edit) whose samples changed
    over ``win`` (tile-local rows and columns, clipped to the tile); True when only the window was written."""
    if gpu.fmt == "float32":  # metres as they are: the same meaning whatever the edit
        qz = metres_as_codes(tile.heights)
    else:
        qz = quantize(tile.heights, getattr(tile, "source_step", None))
    same = (qz.offset, qz.step, qz.base) == (gpu.offset, gpu.step, gpu.base)
    n, heights = gpu.n, cast(Any, gpu.heights)  # a moderngl texture
    if not (same and win.empty):
        q = np.ascontiguousarray(qz.q)
        mips = code_mips(q)
        if same:
            heights.write(np.ascontiguousarray(q[win.slices()]), viewport=_viewport(win.i0, win.i1, win.j0, win.j1))
            write_mips(gpu.maxmip, mips, texel_windows(n, win))
        else:
            heights.write(q)
            write_mips(gpu.maxmip, mips)
    gpu.offset, gpu.step, gpu.base, gpu.quant_error = qz.offset, qz.step, qz.base, qz.error
    gpu.row, gpu.bounds = tile_row(gpu, tile), (tile.clip, tile.zmin, tile.zmax)
    return same


def write_mips(tex, mips, windows=None) -> None:
    """Write host max-mip levels (``code_mips``: levels 1..log2 N, uint16 or float32) into a tile's max-mip texture,
    level k of the texture from ``mips[k]``: each level whole, or only each level's (r0, r1, c0, c1) texel window
    of ``windows``."""
    for k, m in enumerate(mips):
        r0, r1, c0, c1 = (0, m.shape[0], 0, m.shape[1]) if windows is None else windows[k]
        if r1 > r0 and c1 > c0:
            write_red_level(tex, k, m[r0:r1, c0:c1], c0, r0)


def _viewport(r0: int, r1: int, c0: int, c1: int) -> tuple[int, int, int, int]:
    """(x, y, width, height) of rows [r0, r1) and columns [c0, c1), as texture writes take it."""
    return c0, r0, c1 - c0, r1 - r0


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
