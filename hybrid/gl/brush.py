"""Terrain edits on the GPU: the brush pass over resident R32F heights, and the CPU copy following it.

``GpuHeights`` holds a terrain's full-resolution heights (metres, relative to the origin z) in one R32F texture,
texel (j, i) = sample (i, j), rows south to north. ``BrushPass`` applies a brush (``hybrid.terrain.edits``) to such
a texture in place with two compute dispatches over the touched window only (a snapshot of the window grown by one
sample, then the brush reading it), in the CPU reference's float32 arithmetic. ``edit`` runs it and then writes the
window back to the height field's CPU array (write-through: the GPU changes first, the CPU copy follows).
"""

from __future__ import annotations

import ctypes

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import _gl_function, gl_bytes, max_texture_size
from hybrid.gl.programs import compute_shader
from hybrid.terrain.edits import Brush, BrushParams, Window, brush_params, touched
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

    def apply(self, tex, p: BrushParams, grid: tuple[int, int]) -> Window:
        """Apply brush p to the R32F heights texture ``tex`` of a (rows, cols) grid in place over the touched
        window only; returns that window (empty: no dispatch)."""
        rows, cols = grid
        win = touched(p, rows, cols)
        if win.empty:
            return win
        size = (win.j1 - win.j0, win.i1 - win.i0)
        scratch = self._scratch(size[0] + 2, size[1] + 2)
        tex.bind_to_image(0, read=True, write=True)
        scratch.bind_to_image(1, read=True, write=True)
        for prog in (self.snapshot, self.brush):
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
            for k, v in values.items():
                if k in prog:
                    prog[k].value = v
            extra = 2 if prog is self.snapshot else 0
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
    """A height field's full-resolution heights on the GPU (one R32F texture) and the brush pass that edits them."""

    def __init__(self, ctx, hf: HeightField):
        limit = max_texture_size(ctx)
        if hf.rows > limit or hf.cols > limit:
            raise TerrabenchError(
                f"editing {hf.name!r} ({hf.cols}x{hf.rows} samples) needs its heights in one "
                f"texture, beyond this GL's limit of {limit} a side"
            )
        self.ctx, self.hf = ctx, hf
        h = np.ascontiguousarray(hf.heights, dtype=np.float32)
        self.texture = ctx.texture((hf.cols, hf.rows), 1, h.tobytes(), dtype="f4")
        self.texture.filter = (ctx.NEAREST, ctx.NEAREST)
        self.brushes = BrushPass(ctx)

    def edit(self, brush: Brush) -> Window:
        """Apply a brush (world metres, hf's frame) on the GPU, then copy the touched window back into hf's CPU
        heights; returns the window (sample rows and columns) that changed."""
        p = brush_params(brush, self.hf)
        win = self.brushes.apply(self.texture, p, (self.hf.rows, self.hf.cols))
        if not win.empty:
            self.hf.heights[win.slices()] = read_r32f_window(self.texture, win)
        return win

    def read(self, win: Window | None = None) -> np.ndarray:
        """float32 heights (metres, rows south to north) of a window of the texture (None: all of it)."""
        return read_r32f_window(self.texture, win or Window(0, self.hf.rows, 0, self.hf.cols))

    @property
    def nbytes(self) -> int:
        """GPU bytes of the heights and the brush pass's scratch image."""
        return gl_bytes(self.texture) + self.brushes.nbytes

    def release(self) -> None:
        """Free the texture and the brush pass."""
        self.texture.release()
        self.brushes.release()
