"""The reference renderer: the full-resolution surface, two triangles per cell, no level of detail.

Every method is measured against it. Cells are split along the (i, j) -> (i+1, j+1) diagonal (south-west
to north-east), the same convention as the pyramid's error and the ray caster's triangle reconstruction.
Colour can be supersampled (k x k samples a pixel, box filtered); hit distance and coverage always come
from one sample at each pixel centre so they compare one to one with any other method.
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np

from hybrid.camera.view import View
from hybrid.contract import FrameStats
from hybrid.errors import TerrabenchError
from hybrid.gl.context import gl_bytes, max_texture_size
from hybrid.gl.programs import program
from hybrid.gl.shading import resolve_mode
from hybrid.gl.target import FrameTarget, RenderResult
from hybrid.gl.textures import terrain_texture
from hybrid.gl.timing import timed
from hybrid.reference_blocks import (
    DEFAULT_BLOCK_SAMPLES,
    Block,
    block_bounds,
    reference_blocks,
    visible_blocks,
)
from hybrid.terrain.edits import Window
from hybrid.terrain.heightfield import HeightField
from hybrid.tiles.byte_lru import ByteLRU
from hybrid.tiles.tiletree import DEFAULT_TAU

ReferenceMode = Literal["texture", "shaded", "height"]
MODES = {m: i for i, m in enumerate(get_args(ReferenceMode))}
RESIDENT_SAMPLES = 1 << 26  # a stored grid up to this many samples is read once and kept on the GPU
HOST_BLOCK_BYTES = 256 << 20  # a streamed grid's blocks kept in host memory between draws, least recently used out


def grid_indices(rows: int, cols: int) -> np.ndarray:
    """uint32 triangle indices of a rows x cols sample grid, 2 CCW triangles a cell, SW-NE diagonal."""
    i, j = np.mgrid[0 : rows - 1, 0 : cols - 1]
    a = (i * cols + j).ravel().astype(np.uint32)
    b, c, d = a + 1, a + np.uint32(cols) + 1, a + np.uint32(cols)
    return np.stack([a, b, c, a, c, d], axis=1).ravel()


class ReferenceRenderer:
    """GPU state of the reference surface of one height field: a height texture and index buffer per block
    (``hybrid.reference_blocks``: blocks within the context's texture limit, so any grid size draws), and the
    colour texture. Grids held in memory keep every block's texture on the GPU; a stored grid beyond
    RESIDENT_SAMPLES streams the blocks a view sees on each draw, so it draws out of core: from a host cache of
    ``host_bytes`` (blocks it holds drawn first, so a view that shows more than it holds still reads only the
    rest), else from disk. ``block_reads`` counts the blocks read from disk."""

    def __init__(
        self, ctx, hf: HeightField, block_samples: int = DEFAULT_BLOCK_SAMPLES, host_bytes: int = HOST_BLOCK_BYTES
    ):
        self.ctx, self.hf = ctx, hf
        self.prog = program(ctx, "hybrid", "reference.vert.glsl", "reference.frag.glsl")
        side = min(int(block_samples), max_texture_size(ctx))
        self.blocks = reference_blocks(hf.rows, hf.cols, side)
        self.lo, self.hi = block_bounds(hf, self.blocks)
        self.resident = isinstance(hf.heights, np.ndarray) or hf.rows * hf.cols <= RESIDENT_SAMPLES
        self.textures: dict = {}  # block index (resident) or block shape (streamed) -> texture
        self.vaos: dict = {}  # block shape -> (index buffer, vertex array)
        self.released = False
        self.drawn_blocks = self.block_reads = 0
        self.host = None if self.resident else ByteLRU(host_bytes)
        if self.resident:
            for k, b in enumerate(self.blocks):
                self.textures[k] = self._texture(b)
        self.texture = terrain_texture(ctx, hf)
        self.triangles = 2 * (hf.rows - 1) * (hf.cols - 1)

    def follow_edit(self, win: Window) -> None:
        """Follow an edit of the terrain's heights over a window of samples: the blocks' bounds, and the resident
        block textures over the window."""
        h = self.hf.heights
        for k, b in enumerate(self.blocks):
            r0, r1, c0, c1 = max(b.r0, win.i0), min(b.r1, win.i1), max(b.c0, win.j0), min(b.c1, win.j1)
            if r0 >= r1 or c0 >= c1:
                continue
            block = h[b.r0 : b.r1, b.c0 : b.c1]
            self.lo[k], self.hi[k] = float(np.min(block)), float(np.max(block))
            if self.resident:
                data = np.ascontiguousarray(h[r0:r1, c0:c1], dtype=np.float32)
                self.textures[k].write(data.tobytes(), viewport=(c0 - b.c0, r0 - b.r0, c1 - c0, r1 - r0))

    def _read(self, b: Block) -> np.ndarray:
        self.block_reads += 1
        return np.ascontiguousarray(self.hf.heights[b.r0 : b.r1, b.c0 : b.c1], dtype=np.float32)

    def _texture(self, b: Block, reuse=None):
        data = self._read(b) if self.host is None else self.host.get((b.r0, b.c0), lambda: self._read(b))
        if reuse is not None:
            reuse.write(data.tobytes())
            return reuse
        tex = self.ctx.texture((b.shape[1], b.shape[0]), 1, data.tobytes(), dtype="f4")
        tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
        return tex

    def _vao(self, shape: tuple[int, int]):
        if shape not in self.vaos:
            ibo = self.ctx.buffer(grid_indices(*shape).tobytes())
            self.vaos[shape] = (ibo, self.ctx.vertex_array(self.prog, [], index_buffer=ibo, index_element_size=4))
        return self.vaos[shape][1]

    @property
    def nbytes(self) -> int:
        """GPU bytes of the height textures, index buffers and colour texture, as the driver reports them."""
        return gl_bytes(*self.textures.values(), *(ibo for ibo, _ in self.vaos.values()), self.texture)

    def draw(self, target: FrameTarget, view: View, mode: str | None = None) -> None:
        """Draw the whole surface into target (which must match the view's size) for the view, block by block."""
        if self.released:
            raise TerrabenchError("this reference renderer was released; make a new one")
        mode = resolve_mode(self.hf, mode, MODES)
        hf = self.hf
        self.prog["full"].value = (hf.cols, hf.rows)
        self.prog["origin_rel"].value = tuple((np.array(hf.origin) - view.eye).astype(np.float32))
        self.prog["spacing"].value = (hf.spacing_x, hf.spacing_y)
        self.prog["view_proj_rel"].write(view.view_proj_rel.T.astype(np.float32).tobytes())
        self.prog["mode"].value = MODES[mode]
        self.prog["hrange"].value = hf.height_range
        self.prog["heights"].value = 0
        if self.texture is not None:
            self.texture.use(1)
            self.prog["tex"].value = 1
        target.use()
        shown = visible_blocks(hf, self.blocks, self.lo, self.hi, view).tolist()
        if self.host is not None:  # held blocks first: each is drawn before a read can evict it
            host = self.host
            shown.sort(key=lambda k: (self.blocks[k].r0, self.blocks[k].c0) not in host)
        for k in shown:
            b = self.blocks[k]
            if self.resident:
                tex = self.textures[k]
            else:
                tex = self.textures[b.shape] = self._texture(b, self.textures.get(b.shape))
            tex.use(0)
            self.prog["grid"].value = (b.shape[1], b.shape[0])
            self.prog["first"].value = (b.c0, b.r0)
            self._vao(b.shape).render(self.ctx.TRIANGLES)
        self.drawn_blocks = len(shown)

    def render(
        self, view: View, tau: float = DEFAULT_TAU, *, mode: str | None = None, supersample: int = 1, maps: bool = False
    ) -> RenderResult:
        """Colour (box-filtered over supersample² samples), hit distance and coverage for a view.

        Same signature as ``hybrid.renderer.Renderer.render``; tau and maps do not apply (no level of
        detail, one strategy). The draw is timed like any method's (counters: triangles, supersample).
        """
        if (
            isinstance(supersample, bool)
            or not isinstance(supersample, (int, np.integer))
            or not (1 <= supersample <= 8)
        ):
            raise TerrabenchError(f"supersample must be an integer in [1, 8], got {supersample!r}")
        limit = int(self.ctx.info["GL_MAX_TEXTURE_SIZE"])  # the render target's real limit
        if view.width * supersample > limit or view.height * supersample > limit:
            raise TerrabenchError(
                f"supersampled viewport {view.width * supersample}x{view.height * supersample} "
                f"exceeds this GL's texture limit of {limit}"
            )
        target = FrameTarget(self.ctx, view.width, view.height)
        try:
            target.clear()
            _, wall, gpu, issue = timed(self.ctx, lambda: self.draw(target, view, mode))
            stats = FrameStats(
                wall_ms=wall,
                plan_ms=0.0,
                draw_ms=wall,
                gpu_ms=gpu,
                issue_ms=issue,
                tiles=1,
                gpu_bytes=self.nbytes,
                shared_bytes=self.nbytes,
                counters={"triangles": self.triangles, "supersample": supersample, "blocks": self.drawn_blocks},
            )
            result = target.read(view, stats)
        finally:
            target.release()
        if supersample > 1:
            big_view = view.with_size(view.width * supersample, view.height * supersample)
            big = FrameTarget(self.ctx, big_view.width, big_view.height)
            try:
                big.clear()
                self.draw(big, big_view, mode)
                c = big.read_colour().astype(np.float32)
            finally:
                big.release()
            c = c.reshape(view.height, supersample, view.width, supersample, 3).mean(axis=(1, 3))
            result.colour = np.clip(np.rint(c), 0, 255).astype(np.uint8)
        return result

    def __enter__(self) -> ReferenceRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def release(self) -> None:
        """Free the GPU objects; the renderer cannot draw afterwards."""
        if self.released:
            return
        objects = [*self.textures.values(), *(o for pair in self.vaos.values() for o in pair), self.texture, self.prog]
        for o in objects:
            if o is not None:
                o.release()
        self.textures, self.vaos, self.released = {}, {}, True
        if self.host is not None:
            self.host.clear()
