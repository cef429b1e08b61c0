"""A ray-cast tile on the GPU: its 16-bit height codes and their max mipmap, and the shadow rays' whole-terrain grid.

A tile is 16-bit height codes (hybrid.tiles.quantize: exact on a 16-bit source's step, else range/65535 with
the error measured) in an R16UI (N+1)² texture, and its max mipmap of codes without level 0 in an R16UI (N/2)²
texture (raycast.maxmip), built on the GPU.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.tiles.quantize import quantize

from .maxmip import tile_nbytes


@dataclass
class GpuTile:
    """One tile on the GPU: R16UI (N+1)² height codes and their R16UI (N/2)² max mipmap (levels 1..log2 N);
    exact byte count; metres = offset + step * (code + base); quant_error: largest |height - dequantised| (m)."""

    heights: Any  # moderngl textures
    maxmip: Any
    n: int
    nbytes: int
    offset: float = 0.0
    step: float = 1.0
    base: int = 0
    quant_error: float = 0.0
    row: np.ndarray | None = None  # tile_row of the tile uploaded (None: a grid, not a tile)
    bounds: tuple = ()  # that tile's clip, zmin and zmax, to tell it from a tile drawn in its place

    @property
    def bytes_per_sample(self) -> float:
        """GPU bytes per height sample held, max mipmap included: nbytes / (N+1)²."""
        return self.nbytes / (self.n + 1) ** 2

    def release(self) -> None:
        """Free both textures."""
        self.heights.release()
        self.maxmip.release()


@dataclass
class ShadowGrid:
    """The whole terrain as one power-of-two grid, for shadow rays (built on the first shadowed draw)."""

    tex: GpuTile
    n: int
    ext: tuple
    zr: tuple
    nbytes: int


def upload_heights(ctx, builder, heights: np.ndarray, source_step=None) -> GpuTile:
    """Heights (N+1)² (N a power of two >= 2; float32 metres relative to origin z) on the GPU as 16-bit codes
    (exact on ``source_step``, hybrid.tiles.quantize), with their max mipmap built there by ``builder``
    (raycast.maxmip.MaxMipBuilder)."""
    h = np.asarray(heights, dtype=np.float32)
    n = h.shape[0] - 1
    if h.ndim != 2 or h.shape[1] != h.shape[0] or n < 2 or n & (n - 1):
        raise TerrabenchError(f"tile heights must be (N+1, N+1) with N a power of two >= 2, got {h.shape}")
    qz = quantize(h, source_step)
    ht = ctx.texture((n + 1, n + 1), 1, np.ascontiguousarray(qz.q).tobytes(), dtype="u2")
    ht.filter = (ctx.NEAREST, ctx.NEAREST)
    mm = builder.build(ht, n)
    return GpuTile(ht, mm, n, tile_nbytes(n), qz.offset, qz.step, qz.base, qz.error)


def shadow_grid(hf, upload) -> ShadowGrid:
    """The terrain's heights padded (edge samples repeated) to a power-of-two grid and put on the GPU by
    ``upload(heights, source_step) -> GpuTile``."""
    h = np.asarray(hf.heights, dtype=np.float32)
    cells = max(h.shape) - 1
    n = 1 << max(1, int(np.ceil(np.log2(max(cells, 2)))))
    pad = np.pad(h, ((0, n + 1 - h.shape[0]), (0, n + 1 - h.shape[1])), mode="edge")
    g = upload(pad, getattr(hf, "source_step", None))
    lo, hi = float(h.min()), float(h.max())
    return ShadowGrid(g, n, (float(h.shape[1] - 1), float(h.shape[0] - 1)), (lo, hi), g.nbytes)
