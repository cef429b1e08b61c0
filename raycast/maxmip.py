"""Maximum mipmaps of a tile: level 0 bounds each cell, level l is the 2x2 maximum of level l-1, down to 1x1.

Texel space of a tile with N cells a side ((N+1)² height samples): level-0 texel (i, j) is cell (i, j), the
square [j, j+1] x [i, i+1]; it holds the largest of the cell's four corner heights, so it bounds every
reconstruction that interpolates those corners (planes, linear planes, triangles, bilinear). Level l texel
(i, j) covers cells [i*2^l, (i+1)*2^l) x [j*2^l, (j+1)*2^l). Heights are float32 metres (relative to the
terrain's origin z), rows south to north. The GPU builder (compute shaders) gives the same bits as
``maxmip_levels`` because a maximum of float32 values is exact.
"""
from __future__ import annotations

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.programs import compute_shader


def _check_heights(heights) -> np.ndarray:
    h = np.asarray(heights)
    if h.ndim != 2 or h.shape[0] != h.shape[1] or h.shape[0] < 3:
        raise TerrabenchError(f"heights must be a square (N+1, N+1) array with N >= 2, got shape {h.shape}")
    n = h.shape[0] - 1
    if n & (n - 1):
        raise TerrabenchError(f"heights must have N+1 samples a side with N a power of two, got N = {n}")
    return h.astype(np.float32, copy=False)


def level_count(n: int) -> int:
    """Number of max-mip levels of a tile of n cells a side (n a power of two): log2(n) + 1."""
    if isinstance(n, bool) or int(n) != n or n < 1 or int(n) & (int(n) - 1):
        raise TerrabenchError(f"cells per side must be a power of two >= 1, got {n!r}")
    return int(n).bit_length()


def maxmip_levels(heights) -> list[np.ndarray]:
    """Max-mip pyramid (float32, metres) of an (N+1)² tile: [N x N cell maxima, N/2 x N/2, ..., 1 x 1]."""
    h = _check_heights(heights)
    base = np.maximum(np.maximum(h[:-1, :-1], h[:-1, 1:]), np.maximum(h[1:, :-1], h[1:, 1:]))
    levels = [np.ascontiguousarray(base)]
    while levels[-1].shape[0] > 1:
        a = levels[-1]
        m = a.shape[0] // 2
        levels.append(np.ascontiguousarray(a.reshape(m, 2, m, 2).max(axis=(1, 3))))
    return levels


def maxmip_nbytes(n: int) -> int:
    """Bytes of the float32 max-mip pyramid of an n-cell tile: 4 * (n² + n²/4 + ... + 1), about 4/3 of level 0."""
    return sum(4 * (n >> l) ** 2 for l in range(level_count(n)))


class MaxMipBuilder:
    """Compute-shader programs that fill a tile's max-mip texture from its height texture, level by level."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.base = compute_shader(ctx, "raycast", "maxmip_base.comp.glsl")
        self.reduce = compute_shader(ctx, "raycast", "maxmip_reduce.comp.glsl")

    def allocate(self, n: int):
        """An R32F n x n texture with all log2(n)+1 mip levels allocated (contents undefined)."""
        levels = level_count(n)
        tex = self.ctx.texture((n, n), 1, dtype="f4")
        if levels > 1:
            tex.build_mipmaps(0, levels - 1)  # allocates every level; the builder overwrites them
        tex.filter = (self.ctx.NEAREST_MIPMAP_NEAREST, self.ctx.NEAREST)
        tex.repeat_x = tex.repeat_y = False
        return tex

    def build(self, height_tex, n: int, out_tex=None):
        """Fill (or allocate and fill) the max-mip texture of an R32F (n+1)² height texture; returns it."""
        tex = out_tex if out_tex is not None else self.allocate(n)
        height_tex.use(0)
        self.base["heights"].value = 0
        self.base["size"].value = n
        tex.bind_to_image(1, read=False, write=True, level=0)
        g = (n + 7) // 8
        self.base.run(g, g, 1)
        for l in range(1, level_count(n)):
            m = n >> l
            self.ctx.memory_barrier()
            tex.bind_to_image(0, read=True, write=False, level=l - 1)
            tex.bind_to_image(1, read=False, write=True, level=l)
            self.reduce["size"].value = m
            g = (m + 7) // 8
            self.reduce.run(g, g, 1)
        self.ctx.memory_barrier()
        return tex

    def release(self) -> None:
        """Free the programs."""
        self.base.release()
        self.reduce.release()


def read_maxmip(tex, n: int) -> list[np.ndarray]:
    """Read every level of a GPU max-mip texture back as float32 arrays (rows south to north)."""
    out = []
    for l in range(level_count(n)):
        m = n >> l
        out.append(np.frombuffer(tex.read(level=l, alignment=4), dtype=np.float32).reshape(m, m).copy())
    return out
