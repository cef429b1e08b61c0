"""The terrain's outer edges on the GPU, for the shaders' ray_starts_under (hybrid/gl/edges.glsl)."""

from __future__ import annotations

import numpy as np

from hybrid.gl.context import gl_bytes, max_texture_size
from hybrid.gl.programs import set_uniform
from hybrid.terrain.edges import edge_profiles, eye_under, grid_frame
from hybrid.terrain.heightfield import HeightField


def fold_profiles(prof: np.ndarray, width: int) -> np.ndarray:
    """(4 * k, w) float32 rows of the (4, L) edge profiles, each profile wrapped onto k = ceil(L / w) rows of
    w = min(L, width) texels (sample i of side s at row s * k + i // w, column i % w), the last row padded."""
    length = prof.shape[1]
    w = min(length, width)
    k = -(-length // w)
    out = np.zeros((4, k * w), np.float32)
    out[:, :length] = prof
    return out.reshape(4 * k, w)


class TerrainEdges:
    """R32F texture of a terrain's four edge profiles, and the per-view uniforms of edges.glsl. A profile longer
    than the context's widest texture wraps onto further rows (``fold_profiles``)."""

    def __init__(self, ctx, hf: HeightField):
        prof = edge_profiles(hf.heights)
        self.length = prof.shape[1]
        folded = fold_profiles(prof, max_texture_size(ctx))
        self.texture = ctx.texture((folded.shape[1], folded.shape[0]), 1, folded.tobytes(), dtype="f4")
        self.texture.filter = (ctx.NEAREST, ctx.NEAREST)

    @property
    def nbytes(self) -> int:
        """GPU bytes of the texture, as the driver reports them."""
        return gl_bytes(self.texture)

    def bind(self, prog, hf: HeightField, view, unit: int) -> None:
        """Put the texture on texture unit ``unit`` and set prog's edges.glsl uniforms for the view's eye over
        hf (the terrain the texture was made from)."""
        self.texture.use(unit)
        set_uniform(prog, "edges", unit)
        set_uniform(prog, "edge_len", self.length)
        set_uniform(prog, "grid_cells", (float(hf.cols - 1), float(hf.rows - 1)))
        set_uniform(prog, "grid_eye", tuple(float(v) for v in grid_frame(hf, view.eye, np.zeros((1, 3)))[0]))
        set_uniform(prog, "grid_per_m", (1.0 / float(hf.spacing_x), 1.0 / float(hf.spacing_y)))
        set_uniform(prog, "eye_under", eye_under(hf, view.eye))

    def release(self) -> None:
        """Free the texture."""
        self.texture.release()
