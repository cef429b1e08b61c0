"""Per-tile shader parameters of the raster strategies as one std140 uniform block per tile (tile_block.glsl).

A frame's blocks are built as one numpy array and written with one buffer write; drawing a tile binds its
256-byte range. This keeps the CPU's per-frame work to a few calls per tile however many uniforms change.
"""
from __future__ import annotations

import numpy as np

from hybrid.gl.programs import register_include

BLOCK_BYTES = 256              # one block per tile, at a range offset every GL implementation accepts
BLOCK = np.dtype([("origin", "<f4", 4), ("spacing", "<f4", 4), ("clip_rel", "<f4", 4), ("uv", "<f4", 4),
                  ("shape", "<i4", 4), ("nb_delta", "<i4", 4), ("flags", "<i4", 4), ("skirt", "<f4", 4),
                  ("offsets", "<i4", 16), ("starts", "<i4", 16)])
assert BLOCK.itemsize == BLOCK_BYTES


def register_tile_block(ctx) -> None:
    """Make ``#include "raster/tile_block"`` and ``"raster/tile_clip"`` resolve on ctx (the raster strategies
    call it before compiling)."""
    register_include(ctx, "raster/tile_block", "raster", "tile_block.glsl")
    register_include(ctx, "raster/tile_clip", "raster", "tile_clip.glsl")


def skirt_bottom(tile, view) -> float:
    """Eye-relative z (metres) of the lower edge of a tile's skirts: below its lowest point."""
    return float(tile.zmin - view.eye[2] - 1.0 - 0.01 * max(tile.spacing_x, tile.spacing_y))


def tile_blocks(hf, view, items, skirts: dict | None = None, culling: bool = True, unit_spacing: bool = False,
                per_tile=None) -> np.ndarray:
    """The blocks of a frame's (gpu, tile, selected) items; ``per_tile(i, gpu, tile, selected, block)`` fills in
    selection fields (offsets, starts, first node); ``unit_spacing`` for meshes whose positions are metres."""
    out = np.zeros(len(items), BLOCK)
    eye = np.asarray(view.eye, dtype=np.float64)
    hf_origin = np.asarray(hf.origin, dtype=np.float64)
    extent = np.asarray(hf.extent, dtype=np.float64)
    for i, (g, tile, sel) in enumerate(items):
        b = out[i]
        sp = np.ones(2) if unit_spacing else np.array([tile.spacing_x, tile.spacing_y], dtype=np.float64)
        b["origin"] = (*(np.asarray(tile.origin, dtype=np.float64) - eye), 0.0)
        b["spacing"] = (sp[0], sp[1], 0.0, 0.0)
        x0, y0, x1, y1 = tile.clip
        b["clip_rel"] = (x0 - eye[0], y0 - eye[1], x1 - eye[0], y1 - eye[1])
        b["uv"] = (*((np.asarray(tile.origin[:2], dtype=np.float64) - hf_origin[:2]) / extent), *(sp / extent))
        b["shape"] = (0, 0, 0, int(sel.key.level))
        b["nb_delta"] = tuple(int(d) for d in getattr(sel, "edge_deltas", (9, 9, 9, 9)))
        b["flags"] = (int((skirts or {}).get(sel.key, 0)), int(bool(culling) and not bool(sel.inside)), 0, 0)
        b["skirt"] = (skirt_bottom(tile, view), 0.0, 0.0, 0.0)
        if per_tile is not None:
            per_tile(i, g, tile, sel, b)
    return out


class TileBlocks:
    """The uniform buffer holding a frame's tile blocks (grown as needed)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.buffer = ctx.buffer(reserve=BLOCK_BYTES * 16)

    def write(self, blocks: np.ndarray) -> None:
        """Upload a frame's blocks."""
        need = max(len(blocks), 1) * BLOCK_BYTES
        if self.buffer.size < need:
            self.buffer.release()
            self.buffer = self.ctx.buffer(reserve=need)
        if len(blocks):
            self.buffer.write(blocks.tobytes())

    def bind(self, i: int) -> None:
        """Make tile i's block the TileBlock of every program (binding 0)."""
        self.buffer.bind_to_uniform_block(0, offset=i * BLOCK_BYTES, size=BLOCK_BYTES)

    @property
    def nbytes(self) -> int:
        """Bytes of the uniform buffer."""
        return int(self.buffer.size)

    def release(self) -> None:
        """Free the buffer."""
        self.buffer.release()
