"""Procedural deformations on the GPU: the base heights under them, and the pass composing them at a time.

``GpuDeformations`` extends a terrain's ``hybrid.gl.brush.GpuHeights`` once a deformation is added: it keeps the
base heights (every brush, no deformation; metres relative to the origin z) in R32F blocks laid out as the heights',
and at a clock time ``step`` composes heights = base + every deformation's displacement (``hybrid.terrain.deform``)
over the windows of the deformations whose own time moved, on the GPU only. A brush then edits the base
(``edit``): the brush pass on the base texture, the composition over the brush's window, the window written
through to the CPU heights. The heights at a time are a function of (base, deformations, time) alone, so every
run draws the same frames whatever the steps before.
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.brush import GROUP, GpuHeights, HeightBlock, height_blocks, read_blocks
from hybrid.gl.context import gl_bytes
from hybrid.gl.programs import compute_shader
from hybrid.terrain.deform import DeformParams, deform_window
from hybrid.terrain.edits import Brush, Window, brush_params

MAX_DEFORMATIONS = 16  # deformations a terrain holds at once (the composing loop's cap)


class GpuDeformations:
    """The base heights of a terrain's GPU heights and the deformations composed over them."""

    def __init__(self, gpu: GpuHeights):
        self.gpu, self.ctx = gpu, gpu.ctx
        self.base: list[HeightBlock] = height_blocks(self.ctx, gpu.read(), gpu.limit)  # the heights' layout
        self.prog = compute_shader(self.ctx, "hybrid.gl", "deform.comp.glsl", {"MAX_DEF": MAX_DEFORMATIONS})
        self.params: list[DeformParams] = []
        self.taus: list[float | None] = []  # each deformation's own time (s) as last composed
        self.time = 0.0  # the clock time (s) of the last step

    def add(self, p: DeformParams) -> None:
        """Add a deformation (texel space); it changes the heights from the next ``step``."""
        if len(self.params) >= MAX_DEFORMATIONS:
            raise TerrabenchError(f"a terrain holds at most {MAX_DEFORMATIONS} deformations at once")
        self.params.append(p)
        self.taus.append(None)

    def _compose(self, win: Window) -> None:
        """Set the heights over a window to base + every deformation's displacement at the last step's time."""
        n = len(self.params)
        disc = np.zeros((MAX_DEFORMATIONS, 4), np.float32)
        motion = np.zeros((MAX_DEFORMATIONS, 4), np.float32)
        for k, p in enumerate(self.params):
            q = p.disc
            disc[k] = (q.cj, q.ci, np.float32(q.radius * q.radius), p.code)
            motion[k] = (p.amplitude, p.wavelength, p.speed, p.tau(self.time))
        prog = self.prog
        for name, value in (("spacing", (self.gpu.hf.spacing_x, self.gpu.hf.spacing_y)), ("count", n)):
            prog[name].value = value
        prog["disc"].write(disc.tobytes())
        prog["motion"].write(motion.tobytes())
        for heights, base in zip(self.gpu.blocks, self.base):
            part = heights.part(win)
            if part.empty:
                continue
            prog["win0"].value = (part.j0, part.i0)
            prog["win_size"].value = (part.j1 - part.j0, part.i1 - part.i0)
            prog["origin"].value = (heights.j0, heights.i0)
            heights.texture.bind_to_image(0, read=True, write=True)
            base.texture.bind_to_image(1, read=True, write=False)
            prog.run(-(-(part.j1 - part.j0) // GROUP), -(-(part.i1 - part.i0) // GROUP), 1)
        self.ctx.memory_barrier()

    def step(self, t: float) -> list[Window]:
        """Compose the heights at clock time t (s) on the GPU over the windows of the deformations whose own time
        moved since the last step; returns those windows (sample rows and columns; the CPU copy does not follow)."""
        self.time = float(t)
        rows, cols = self.gpu.hf.rows, self.gpu.hf.cols
        moved = []
        for k, p in enumerate(self.params):
            tau = p.tau(self.time)
            if tau != self.taus[k]:
                moved.append(deform_window(p, rows, cols))
                self.taus[k] = tau
        for win in moved:
            if not win.empty:
                self._compose(win)
        return [w for w in moved if not w.empty]

    def edit(self, brush: Brush) -> Window:
        """Apply a brush (world metres) to the base heights on the GPU, compose the heights over its window at the
        last step's time, and write that window through to the CPU heights; returns the window."""
        hf = self.gpu.hf
        win = self.gpu.brushes.apply(self.base, brush_params(brush, hf), (hf.rows, hf.cols))
        if not win.empty:
            self._compose(win)
            hf.heights[win.slices()] = read_blocks(self.gpu.blocks, win)
        return win

    def read_base(self, win: Window | None = None) -> np.ndarray:
        """float32 base heights (metres, rows south to north) of a window (None: the whole grid)."""
        return read_blocks(self.base, win or Window(0, self.gpu.hf.rows, 0, self.gpu.hf.cols))

    @property
    def nbytes(self) -> int:
        """GPU bytes of the base heights."""
        return sum(gl_bytes(b.texture) for b in self.base)

    def release(self) -> None:
        """Free the base heights and the program."""
        for b in self.base:
            b.texture.release()
        self.prog.release()
