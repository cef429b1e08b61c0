"""The reference renderer: the full-resolution surface, two triangles per cell, no level of detail.

Every method is measured against it. Cells are split along the (i, j) -> (i+1, j+1) diagonal (south-west
to north-east), the same convention as the pyramid's error and the ray caster's triangle reconstruction.
Colour can be supersampled (k x k samples a pixel, box filtered); hit distance and coverage always come
from one sample at each pixel centre so they compare one to one with any other method.
"""
from __future__ import annotations

import numpy as np

from .errors import TerrabenchError
from .heightfield import HeightField
from .shaders import load_source
from .target import FrameTarget, RenderResult
from .view import View

MODES = {"texture": 0, "shaded": 1, "height": 2}


def grid_indices(rows: int, cols: int) -> np.ndarray:
    """uint32 triangle indices of a rows x cols sample grid, 2 CCW triangles a cell, SW-NE diagonal."""
    i, j = np.mgrid[0:rows - 1, 0:cols - 1]
    a = (i * cols + j).ravel().astype(np.uint32)
    b, c, d = a + 1, a + np.uint32(cols) + 1, a + np.uint32(cols)
    return np.stack([a, b, c, a, c, d], axis=1).ravel()


def resolve_mode(hf: HeightField, mode: str | None) -> str:
    """The shading mode to use: 'texture' when the terrain has one, else 'shaded', unless given."""
    if mode is None:
        return "texture" if hf.texture is not None else "shaded"
    if mode not in MODES:
        raise TerrabenchError(f"unknown shading mode {mode!r}; choose one of {', '.join(MODES)}")
    if mode == "texture" and hf.texture is None:
        raise TerrabenchError(f"terrain {hf.name!r} has no texture; use shading 'shaded' or 'height'")
    return mode


class ReferenceRenderer:
    """GPU state of the reference surface of one height field (height texture, index buffer, texture)."""

    def __init__(self, ctx, hf: HeightField):
        self.ctx, self.hf = ctx, hf
        self.prog = ctx.program(
            vertex_shader=load_source("hybrid", "reference.vert.glsl"),
            fragment_shader=load_source("hybrid", "reference.frag.glsl").replace(
                "//#include shading.glsl", load_source("hybrid", "shading.glsl")),
        )
        self.heights = ctx.texture((hf.cols, hf.rows), 1, hf.heights.tobytes(), dtype="f4")
        self.heights.filter = (ctx.NEAREST, ctx.NEAREST)
        self.ibo = ctx.buffer(grid_indices(hf.rows, hf.cols).tobytes())
        self.vao = ctx.vertex_array(self.prog, [], index_buffer=self.ibo, index_element_size=4)
        self.texture = None
        if hf.texture is not None:
            self.texture = ctx.texture((hf.cols - 1, hf.rows - 1), 3, np.ascontiguousarray(hf.texture).tobytes())
            self.texture.build_mipmaps()
            self.texture.anisotropy = 16.0
            self.texture.repeat_x = self.texture.repeat_y = False
        self.triangles = 2 * (hf.rows - 1) * (hf.cols - 1)

    @property
    def nbytes(self) -> int:
        """GPU bytes of the height texture, index buffer and colour texture (with its mipmaps)."""
        n = self.heights.width * self.heights.height * 4 + self.ibo.size
        if self.texture is not None:
            w, h = self.texture.size
            while True:
                n += w * h * 3
                if w == 1 and h == 1:
                    break
                w, h = max(w // 2, 1), max(h // 2, 1)
        return n

    def draw(self, target: FrameTarget, view: View, mode: str | None = None) -> None:
        """Draw the whole surface into target (which must match the view's size) for the view."""
        mode = resolve_mode(self.hf, mode)
        hf = self.hf
        self.prog["grid"].value = (hf.cols, hf.rows)
        self.prog["origin_rel"].value = tuple((np.array(hf.origin) - view.eye).astype(np.float32))
        self.prog["spacing"].value = hf.spacing
        self.prog["view_proj_rel"].write(view.view_proj_rel.T.astype(np.float32).tobytes())
        self.prog["mode"].value = MODES[mode]
        self.prog["hrange"].value = hf.height_range
        self.heights.use(0)
        self.prog["heights"].value = 0
        if self.texture is not None:
            self.texture.use(1)
            self.prog["tex"].value = 1
        target.use()
        self.vao.render(self.ctx.TRIANGLES)

    def render(self, view: View, mode: str | None = None, supersample: int = 1) -> RenderResult:
        """Colour (box-filtered over supersample² samples), hit distance and coverage for a view."""
        if isinstance(supersample, bool) or not isinstance(supersample, (int, np.integer)) or not (1 <= supersample <= 8):
            raise TerrabenchError(f"supersample must be an integer in [1, 8], got {supersample!r}")
        if view.width * supersample > 16384 or view.height * supersample > 16384:
            raise TerrabenchError(f"supersampled viewport {view.width * supersample}x{view.height * supersample} exceeds 16384")
        target = FrameTarget(self.ctx, view.width, view.height)
        try:
            target.clear()
            self.draw(target, view, mode)
            result = target.read(view, {"triangles": self.triangles})
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
        result.stats["supersample"] = supersample
        return result

    def release(self) -> None:
        """Free the GPU objects."""
        for o in (self.vao, self.ibo, self.heights, self.texture, self.prog):
            if o is not None:
                o.release()
