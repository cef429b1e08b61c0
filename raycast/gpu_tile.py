"""A ray-cast tile on the GPU: its 16-bit height codes and their max mipmap, and the shadow rays' whole-terrain grid.

A tile is 16-bit height codes (hybrid.tiles.quantize: exact on a 16-bit source's step, else range/65535 with
the error measured) in an R16UI (N+1)² texture, and its max mipmap of codes without level 0 in a storage buffer
(raycast.mip_buffer). A tile's codes and max mipmap are made on the host (``prepare_heights``: CPU work that a
tile store's loader thread does ahead of the frame) and put on the GPU as they are (``upload_prepared``: the
frame's part, a texture and a buffer filled). A grid's max mipmap is an R16UI (N/2)² texture built on the GPU
(``upload_heights``). A tile may instead hold float32 metres (an R32F texture and a float32 buffer,
``heights='float32'``, raycast.options): the baseline that measures what the codes cost.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.tiles.quantize import Quantized, quantize

from .maxmip import heights_nbytes, maxmip_nbytes, tile_nbytes
from .mip_buffer import level_views, mip_buffer


@dataclass
class GpuTile:
    """One tile on the GPU: R16UI (N+1)² height codes and their max mipmap (levels 1..log2 N) in a storage buffer
    (a grid's: an R16UI (N/2)² texture), or float32 metres where ``fmt`` is 'float32'; exact byte count;
    metres = offset + step * (code + base); quant_error: largest |height - dequantised| (m)."""

    heights: Any  # a moderngl texture
    maxmip: Any  # a moderngl buffer (raycast.mip_buffer), or a texture for a shadow grid (upload_heights)
    n: int
    nbytes: int
    offset: float = 0.0
    step: float = 1.0
    base: int = 0
    quant_error: float = 0.0
    row: np.ndarray | None = None  # tile_row of the tile uploaded (None: a grid, not a tile)
    bounds: tuple = ()  # that tile's clip, zmin and zmax, to tell it from a tile drawn in its place
    fmt: str = "uint16"  # texel format: 'uint16' codes or 'float32' metres (raycast.options.HeightFormat)
    host: Any = None  # the codes kept on the host once an edit reached the tile (raycast.edit.HostCodes)

    @property
    def bytes_per_sample(self) -> float:
        """GPU bytes per height sample held, max mipmap included: nbytes / (N+1)²."""
        return self.nbytes / (self.n + 1) ** 2

    def release(self) -> None:
        """Free the height texture and the max mipmap."""
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


@dataclass(frozen=True)
class HostTile:
    """A tile's ray-cast upload made on the host: its 16-bit codes and their max mipmap (levels 1..log2 N, uint16),
    or float32 metres and their max mipmap (codes.q float32, offset 0, step 1)."""

    codes: Quantized
    mips: tuple[np.ndarray, ...]

    @property
    def nbytes(self) -> int:
        """Host bytes held: the codes and every mip level."""
        return int(self.codes.q.nbytes + sum(m.nbytes for m in self.mips))


def _check_tile(heights) -> np.ndarray:
    """Float32 (N+1)² heights with N a power of two >= 2, else refused."""
    h = np.asarray(heights, dtype=np.float32)
    n = h.shape[0] - 1
    if h.ndim != 2 or h.shape[1] != h.shape[0] or n < 2 or n & (n - 1):
        raise TerrabenchError(f"tile heights must be (N+1, N+1) with N a power of two >= 2, got {h.shape}")
    return h


def code_mips(q: np.ndarray) -> tuple[np.ndarray, ...]:
    """Max-mip levels 1..log2 N of (N+1)² uint16 codes or float32 metres (``raycast.maxmip.maxmip_levels(q)[1:]``):
    level 1 is the largest value of each 3 x 3 samples at stride 2 (its 2 x 2 cells' corners), each next one a
    2 x 2 maximum; views of one array made in one compiled pass (``raycast.mip_loops``)."""
    from .mip_loops import code_mip_levels

    q = np.asarray(q)
    flat = code_mip_levels(np.ascontiguousarray(q, dtype=np.float32 if q.dtype == np.float32 else np.uint16))
    return level_views(flat, q.shape[0] - 1)


def metres_as_codes(heights) -> Quantized:
    """A tile's float32 heights (metres relative to origin z) as the 'codes' of a float32 tile: the metres
    themselves, offset 0, step 1, exact."""
    return Quantized(np.ascontiguousarray(heights, dtype=np.float32), 0.0, 1.0, 0, 0.0)


def prepare_heights(heights, source_step=None, fmt: str = "uint16") -> HostTile:
    """A tile's (N+1)² heights (float32 metres relative to origin z) as 16-bit codes (exact on ``source_step``),
    or as float32 metres where ``fmt`` is 'float32', with their max mipmap, on the host: everything of its upload
    that needs no GL context."""
    if fmt == "float32":
        qf = metres_as_codes(_check_tile(heights))
        return HostTile(qf, code_mips(qf.q))
    qz = quantize(_check_tile(heights), source_step)
    q = np.ascontiguousarray(qz.q)
    return HostTile(Quantized(q, qz.offset, qz.step, qz.base, qz.error), code_mips(q))


def upload_prepared(ctx, host: HostTile) -> GpuTile:
    """Put a host-prepared tile on the GPU: its codes (or float32 metres) in a texture and its max mipmap in a
    storage buffer, filled as they are."""
    qz = host.codes
    n, wide = qz.q.shape[0] - 1, qz.q.dtype == np.float32
    ht = ctx.texture((n + 1, n + 1), 1, qz.q, dtype="f4" if wide else "u2", alignment=1)
    ht.filter = (ctx.NEAREST, ctx.NEAREST)
    mm = mip_buffer(ctx, host.mips)
    fmt = "float32" if wide else "uint16"
    return GpuTile(ht, mm, n, tile_nbytes(n, qz.q.dtype.itemsize), qz.offset, qz.step, qz.base, qz.error, fmt=fmt)


def upload_heights(ctx, builder, heights: np.ndarray, source_step=None) -> GpuTile:
    """Heights (N+1)² (N a power of two >= 2; float32 metres relative to origin z) on the GPU as 16-bit codes
    (exact on ``source_step``, hybrid.tiles.quantize), with their max mipmap built there by ``builder``
    (raycast.maxmip.MaxMipBuilder)."""
    h = _check_tile(heights)
    n = h.shape[0] - 1
    qz = quantize(h, source_step)
    ht = ctx.texture((n + 1, n + 1), 1, np.ascontiguousarray(qz.q).tobytes(), dtype="u2")
    ht.filter = (ctx.NEAREST, ctx.NEAREST)
    mm = builder.build(ht, n)
    return GpuTile(ht, mm, n, heights_nbytes(n) + maxmip_nbytes(n), qz.offset, qz.step, qz.base, qz.error)


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
