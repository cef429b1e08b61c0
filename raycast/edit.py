"""The ray caster following an edit: a resident tile's codes and max mipmap refreshed where the heights changed.

A tile's 16-bit codes (``hybrid.tiles.quantize``) keep their meaning while the tile's offset, step and base stay
the same: then only the codes of the changed samples are written and only the max-mip texels over them
(``raycast.maxmip.texel_windows``). An edit that changes the tile's quantisation (its height range, or heights
leaving the source's step) changes every code, and the whole tile is written again into the same texture and
buffer. From its first edit a tile keeps its codes, max mipmap and per-row summaries on the host (``HostCodes``),
so that a later edit re-makes the window's codes and texels only (``raycast.edit_loops``) where re-quantising the
whole tile cost more than the rest of the follow. The max mipmap is written level by level, the window's whole
rows in one buffer write a level (``raycast.mip_buffer.write_mip_rows``), where building it on the GPU took a
dispatch and a barrier a level (on a CPU rasterizer each of those costs as much as the whole write).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from hybrid.terrain.edits import Window
from hybrid.tiles.quantize import Q_MAX

from .gpu_tile import GpuTile
from .maxmip import texel_windows
from .mip_buffer import level_views, write_mip_rows
from .tile_params import tile_row


@dataclass
class HostCodes:
    """A resident tile's codes and max mipmap kept on the host from its first edit (``raycast.edit_loops``):
    codes q ((N+1)², uint16 or float32 metres), max-mip levels 1..log2 N in one flat array, per-row lowest,
    highest and off-step counts (3, N+1), per-row largest errors (N+1) and the quantisation (offset, step, base,
    kind)."""

    q: np.ndarray
    flat: np.ndarray
    sums: np.ndarray
    err: np.ndarray
    params: np.ndarray

    @classmethod
    def empty(cls, n: int, dtype) -> HostCodes:
        """Arrays for a tile of n cells, filled by its first follow."""
        levels = sum((n >> k) ** 2 for k in range(1, n.bit_length()))
        rows = np.zeros(n + 1)
        return cls(np.zeros((n + 1, n + 1), dtype), np.zeros(levels, dtype), np.zeros((3, n + 1)), rows, np.zeros(4))


def follow_tile(gpu: GpuTile, tile, win: Window) -> bool:
    """Bring a resident tile up to date with ``tile`` (the pyramid's tile after the edit) whose samples changed
    over ``win`` (tile-local rows and columns, clipped to the tile); True when only the window was written. The
    first follow of a tile makes its host codes whole; later ones re-make the window's (``raycast.edit_loops``)."""
    from .edit_loops import follow_codes, update_mips
    from .mip_loops import code_mip_levels

    n, whole = gpu.n, gpu.host is None
    wide = gpu.fmt == "float32"  # metres as they are: the same meaning whatever the edit
    if whole:
        gpu.host = HostCodes.empty(n, np.float32 if wide else np.uint16)
        gpu.host.params[:] = (gpu.offset, gpu.step, gpu.base, -1)
    s, h = gpu.host, np.ascontiguousarray(tile.heights, dtype=np.float32)
    wins = np.array(texel_windows(n, win), dtype=np.int64).reshape(-1, 4)
    if wide:
        if whole:  # code_mip_levels over a whole tile, as follow_codes makes it: several times update_mips'
            s.q[:] = h
            s.flat[:] = code_mip_levels(s.q)
            levels = len(wins)
        else:
            s.q[win.slices()] = h[win.slices()]
            levels = update_mips(s.q, s.flat, wins)
        error, same = 0.0, True
    else:
        step = getattr(tile, "source_step", None)
        src = np.array(step if step is not None else (-1.0, 0.0), dtype=np.float64)
        w = np.array([win.i0, win.i1, win.j0, win.j1], dtype=np.int64)
        error, same, levels = follow_codes(h, s.q, s.flat, s.sums, s.err, s.params, w, wins, src, whole, float(Q_MAX))
    mips, heights = level_views(s.flat, n), cast(Any, gpu.heights)  # a moderngl texture
    if not same:
        heights.write(s.q)
        write_mip_rows(gpu.maxmip, mips)
    elif not win.empty:
        heights.write(np.ascontiguousarray(s.q[win.slices()]), viewport=_viewport(win.i0, win.i1, win.j0, win.j1))
        write_mip_rows(gpu.maxmip, mips if whole else mips[:levels], wins)
    gpu.offset, gpu.step, gpu.base = float(s.params[0]), float(s.params[1]), int(s.params[2])
    gpu.quant_error = float(error)
    gpu.row, gpu.bounds = tile_row(gpu, tile), (tile.clip, tile.zmin, tile.zmax)
    return bool(same)


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
