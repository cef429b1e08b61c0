"""Terrain edits on the GPU: the brush pass over resident R32F heights, and the CPU copy following it.

``GpuHeights`` holds a terrain's full-resolution heights (metres, relative to the origin z) in R32F textures,
texel (j, i) = sample (i, j), rows south to north: one texture where the grid fits the GL's size limit, else
blocks of equal size that tile the grid without overlap (``HeightBlock``), so that a grid of any size is edited.
``BrushPass`` applies a brush (``hybrid.terrain.edits``) in place with one compute dispatch for up to four of the
blocks the touched window meets, in the CPU reference's float32 arithmetic; the smooth brush, which reads its neighbours, first
snapshots the window grown by one sample into one scratch image and reads that, so that across block borders it
reads the heights before the edit, as in one texture. ``edit`` runs it and then writes the window back to the
height field's CPU array (write-through: the GPU changes first, the CPU copy follows).
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from typing import Any

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import _gl_function, gl_bytes, max_texture_size
from hybrid.gl.programs import compute_shader
from hybrid.terrain.edits import KINDS, Brush, BrushParams, Window, brush_params, touched
from hybrid.terrain.heightfield import HeightField

GROUP = 8  # the pass's work group side


def read_r32f_window(tex, win: Window) -> np.ndarray:
    """float32 (rows, cols) of an R32F texture's texels over a window of samples (glGetTextureSubImage)."""
    u, i = ctypes.c_uint, ctypes.c_int
    rows, cols = win.i1 - win.i0, win.j1 - win.j0
    out = np.zeros((rows, cols), np.float32)
    _gl_function(b"glPixelStorei", u, i)(0x0D05, 4)  # GL_PACK_ALIGNMENT
    sub = _gl_function(b"glGetTextureSubImage", u, i, i, i, i, i, i, i, u, u, i, ctypes.c_void_p)
    sub(tex.glo, 0, win.j0, win.i0, 0, cols, rows, 1, 0x1903, 0x1406, out.nbytes, out.ctypes.data)  # RED, FLOAT
    return out


@dataclass(frozen=True)
class HeightBlock:
    """One R32F texture of a grid's heights: samples [i0, i0 + rows) x [j0, j0 + cols), texel = sample - (i0, j0)."""

    texture: Any  # a moderngl Texture
    i0: int
    j0: int
    rows: int
    cols: int

    @property
    def window(self) -> Window:
        """The grid's samples this block holds."""
        return Window(self.i0, self.i0 + self.rows, self.j0, self.j0 + self.cols)

    def part(self, win: Window) -> Window:
        """The samples of ``win`` this block holds (grid coordinates; empty where it holds none)."""
        return self.window.intersection(win)


def block_starts(n: int, limit: int) -> list[int]:
    """First samples of the fewest equal blocks (at most ``limit`` samples each) that cover n samples."""
    count = -(-n // limit)
    side = -(-n // count)
    return list(range(0, n, side))


def height_blocks(ctx, heights: np.ndarray, limit: int) -> list[HeightBlock]:
    """R32F textures of float32 heights (rows, cols), in blocks of at most ``limit`` texels a side that tile the grid
    without overlap (``block_starts``)."""
    rows, cols = heights.shape
    out = []
    row_starts, col_starts = block_starts(rows, limit), block_starts(cols, limit)
    for i0, i1 in zip(row_starts, [*row_starts[1:], rows], strict=True):
        for j0, j1 in zip(col_starts, [*col_starts[1:], cols], strict=True):
            r, c = i1 - i0, j1 - j0
            part = np.ascontiguousarray(heights[i0:i1, j0:j1], dtype=np.float32)
            tex = ctx.texture((c, r), 1, part.tobytes(), dtype="f4")
            tex.filter = (ctx.NEAREST, ctx.NEAREST)
            out.append(HeightBlock(tex, i0, j0, r, c))
    return out


def read_blocks(blocks: list[HeightBlock], win: Window) -> np.ndarray:
    """float32 heights (rows, cols) of a window of samples, from the blocks that hold it."""
    out = np.zeros((win.i1 - win.i0, win.j1 - win.j0), np.float32)
    for b in blocks:
        part = b.part(win)
        if part.empty:
            continue
        local = Window(part.i0 - b.i0, part.i1 - b.i0, part.j0 - b.j0, part.j1 - b.j0)
        out[part.i0 - win.i0 : part.i1 - win.i0, part.j0 - win.j0 : part.j1 - win.j0] = read_r32f_window(
            b.texture, local
        )
    return out


BLOCKS_PER_PASS = 4  # height blocks one brush dispatch reads and writes (brush.comp.glsl's image units)
BLOCK_UNITS = (0, 2, 3, 4)  # their image units (1 is the scratch image)


def _bind_blocks(prog, batch: list[HeightBlock]) -> None:
    """Bind up to four height blocks to the brush program's image units, with their origins and sizes (units
    past the batch repeat its first block, which the shader never selects for them)."""
    for unit, b in zip(BLOCK_UNITS, batch + batch[:1] * (BLOCKS_PER_PASS - len(batch)), strict=True):
        b.texture.bind_to_image(unit, read=True, write=True)
    pad = [(0, 0)] * (BLOCKS_PER_PASS - len(batch))
    prog["origins"].write(np.array([(b.j0, b.i0) for b in batch] + pad, dtype=np.int32).tobytes())
    prog["blocks"].write(np.array([(b.cols, b.rows) for b in batch] + pad, dtype=np.int32).tobytes())
    prog["nblocks"].value = len(batch)


class BrushPass:
    """The brush compute programs and their scratch image (GPU state shared by every edit of a context)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.snapshot = compute_shader(ctx, "hybrid.gl", "brush.comp.glsl", {"SNAPSHOT": 1})
        self.brush = compute_shader(ctx, "hybrid.gl", "brush.comp.glsl", {"SNAPSHOT": 0})
        self.scratch = None

    def _scratch(self, cols: int, rows: int):
        """An R32F scratch texture of at least cols x rows texels (grown, never shrunk)."""
        s = self.scratch
        if s is None or s.size[0] < cols or s.size[1] < rows:
            if s is not None:
                s.release()
            w, h = (max(cols, s.size[0]), max(rows, s.size[1])) if s is not None else (cols, rows)
            self.scratch = self.ctx.texture((w, h), 1, dtype="f4")
        return self.scratch

    def apply(self, blocks: list[HeightBlock], p: BrushParams, grid: tuple[int, int]) -> Window:
        """Apply brush p to the R32F height blocks of a (rows, cols) grid in place over the touched window only;
        returns that window (empty: no dispatch)."""
        rows, cols = grid
        win = touched(p, rows, cols)
        if win.empty:
            return win
        size = (win.j1 - win.j0, win.i1 - win.i0)
        scratch = self._scratch(size[0] + 2, size[1] + 2)
        scratch.bind_to_image(1, read=True, write=True)
        grown = win.grown(1, rows, cols)
        values = {
            "win0": (win.j0, win.i0),
            "win_size": size,
            "grid": (cols, rows),
            "centre": (p.cj, p.ci),
            "spacing": (p.sx, p.sy),
            "radius2": float(np.float32(p.radius * p.radius)),
            "strength": p.strength,
            "target": p.target,
            "code": p.code,
        }
        passes = [(self.snapshot, grown, 2)] if p.code == KINDS["smooth"] else []  # only smooth reads neighbours
        values["direct"] = not passes
        for prog, reach, extra in (*passes, (self.brush, win, 0)):
            for k, v in values.items():
                if k in prog:
                    prog[k].value = v
            # the blocks the window (or the samples its snapshot reads, clamped to the grid) meets, up to four a
            # dispatch; the snapshot whole before any block is brushed: borders read the old heights
            met = [b for b in blocks if not b.part(reach).empty]
            for first in range(0, len(met), BLOCKS_PER_PASS):
                _bind_blocks(prog, met[first : first + BLOCKS_PER_PASS])
                prog.run(-(-(size[0] + extra) // GROUP), -(-(size[1] + extra) // GROUP), 1)
            self.ctx.memory_barrier()
        return win

    @property
    def nbytes(self) -> int:
        """GPU bytes of the scratch image, as the driver reports them."""
        return gl_bytes(self.scratch) if self.scratch is not None else 0

    def release(self) -> None:
        """Free the programs and the scratch image."""
        for o in (self.snapshot, self.brush, self.scratch):
            if o is not None:
                o.release()
        self.scratch = None


class GpuHeights:
    """A height field's full-resolution heights on the GPU (R32F blocks of at most ``limit`` texels a side, the
    GL's size limit by default: one texture where the grid fits) and the brush pass that edits them."""

    def __init__(self, ctx, hf: HeightField, limit: int | None = None):
        limit = max_texture_size(ctx) if limit is None else int(limit)
        if limit < 2:
            raise TerrabenchError(f"height blocks need at least 2 texels a side, got {limit}")
        self.ctx, self.hf, self.limit = ctx, hf, limit
        self.blocks = height_blocks(ctx, np.asarray(hf.heights, dtype=np.float32), limit)
        self.brushes = BrushPass(ctx)

    @property
    def texture(self):
        """The one R32F texture of the heights (refused where the grid is held in blocks)."""
        if len(self.blocks) != 1:
            raise TerrabenchError(
                f"{self.hf.name!r} ({self.hf.cols}x{self.hf.rows} samples) is held in {len(self.blocks)} height "
                "textures, beyond this GL's size limit for one; this use needs one texture"
            )
        return self.blocks[0].texture

    def edit(self, brush: Brush) -> Window:
        """Apply a brush (world metres, hf's frame) on the GPU, then copy the touched window back into hf's CPU
        heights; returns the window (sample rows and columns) that changed."""
        p = brush_params(brush, self.hf)
        win = self.brushes.apply(self.blocks, p, (self.hf.rows, self.hf.cols))
        if not win.empty:
            self.hf.heights[win.slices()] = read_blocks(self.blocks, win)
        return win

    def read(self, win: Window | None = None) -> np.ndarray:
        """float32 heights (metres, rows south to north) of a window of the grid (None: all of it)."""
        return read_blocks(self.blocks, win or Window(0, self.hf.rows, 0, self.hf.cols))

    @property
    def nbytes(self) -> int:
        """GPU bytes of the heights and the brush pass's scratch image."""
        return sum(gl_bytes(b.texture) for b in self.blocks) + self.brushes.nbytes

    def release(self) -> None:
        """Free the textures and the brush pass."""
        for b in self.blocks:
            b.texture.release()
        self.brushes.release()
