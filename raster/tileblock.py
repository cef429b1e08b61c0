"""Per-tile shader parameters of the raster strategies as one std140 uniform block per tile (tile_block.glsl).

A frame's blocks are built as one numpy array (what the view leaves unchanged made once per tile:
``static_blocks``; the view's fields per frame: ``view_fields``) and written with one buffer write. A draw of one
tile binds its 256-byte range (the geometry-shader path, skirts); the selection reads all of them as storage;
the indexed path's one multi-draw reads each tile's first fields as instanced attributes.
"""

from __future__ import annotations

import numpy as np

from hybrid.gl.programs import register_include

BLOCK_BYTES = 256  # one block per tile, at a range offset every GL implementation accepts
TILE_BLOCKS_BINDING = 9  # the storage binding of a frame's blocks (tile_block.glsl TILE_BLOCKS_STORAGE)
TILE_BLOCK_BINDING = 0  # the uniform binding of the drawn tile's block (tile_block.glsl TileBlock)
BLOCK_DEFINES = {"TILE_BLOCK_BINDING": TILE_BLOCK_BINDING, "TILE_BLOCKS_BINDING": TILE_BLOCKS_BINDING}
"""The bindings as defines of every program that includes tile_block.glsl."""
BLOCK = np.dtype(
    [
        ("origin", "<f4", 4),
        ("spacing", "<f4", 4),
        ("clip_rel", "<f4", 4),
        ("uv", "<f4", 4),
        ("shape", "<i4", 4),
        ("nb_delta", "<i4", 4),
        ("flags", "<i4", 4),
        ("skirt", "<f4", 4),
        ("offsets", "<i4", 16),
        ("starts", "<i4", 16),
    ]
)
assert BLOCK.itemsize == BLOCK_BYTES
MAX_STARTS = 13  # "starts" entries for level starts; the last three hold where the selection finds
STARTS_HEIGHTS, STARTS_FOUND, STARTS_SEGMENTS = 13, 14, 15  # the tile's heights, its leaf list, its skirts


def register_tile_block(ctx) -> None:
    """Make ``#include "raster/tile_block"``, ``"raster/tile_clip"`` and ``"raster/select_append"`` resolve on ctx
    (the raster strategies call it before compiling)."""
    register_include(ctx, "raster/tile_block", "raster", "tile_block.glsl")
    register_include(ctx, "raster/tile_clip", "raster", "tile_clip.glsl")
    register_include(ctx, "raster/select_append", "raster", "select_append.glsl")


CONSTANT_WORDS = 13  # tile_constants: origin 3, spacing 2, clip 4, zmin, level, level-0 cell (column, row)


def tile_constants(tile) -> np.ndarray:
    """What a tile's block takes from the tile alone, made once per tile: (CONSTANT_WORDS,) float64 world origin
    of sample [0, 0], spacing x and y, clip rectangle (metres), zmin (metres), pyramid level and the level-0 cell
    (column, row) of sample [0, 0]."""
    k = tile.key
    return np.array(
        [
            *tile.origin,
            tile.spacing_x,
            tile.spacing_y,
            *tile.clip,
            tile.zmin,
            k.level,
            k.tx * tile.n << k.level,
            k.ty * tile.n << k.level,
        ],
        dtype=np.float64,
    )


def static_blocks(hf, constants: np.ndarray, unit_spacing: bool = False) -> np.ndarray:
    """(B,) blocks holding only what B tiles' ``tile_constants`` (B, CONSTANT_WORDS) fix whatever the view: sample
    spacing (1 with ``unit_spacing``, for meshes whose positions are metres), texture coordinates of sample [0, 0]
    and per sample, pyramid level and level-0 cell; the rest zero."""
    out = np.zeros(len(constants), BLOCK)
    spacing = constants[:, 3:5]
    sp = np.ones_like(spacing) if unit_spacing else spacing
    extent = np.asarray(hf.extent, dtype=np.float64)
    out["spacing"][:, :2] = sp
    out["uv"][:, :2] = (constants[:, 0:2] - np.asarray(hf.origin[:2], dtype=np.float64)) / extent
    out["uv"][:, 2:] = sp / extent
    out["shape"][:, 3] = constants[:, 10]
    out["flags"][:, 2:] = constants[:, 11:13]
    return out


def view_fields(
    blocks: np.ndarray, view, constants: np.ndarray, sels, skirts: dict | None = None, culling: bool = True
) -> np.ndarray:
    """Fill in the view's fields of a frame's blocks (in place; returned): origin, clip rectangle and skirt bottom
    relative to the eye (metres), from the items' ``tile_constants`` (B, CONSTANT_WORDS); neighbour level deltas,
    skirt edges and culling from their selections ``sels`` (B ``SelectedTile``s)."""
    eye = np.asarray(view.eye, dtype=np.float64)
    blocks["origin"][:, :3] = constants[:, 0:3] - eye
    blocks["clip_rel"] = constants[:, 5:9] - eye[[0, 1, 0, 1]]
    blocks["nb_delta"] = [s.edge_deltas for s in sels]
    if skirts:
        blocks["flags"][:, 0] = [skirts.get(s.key, 0) for s in sels]
    if culling:
        blocks["flags"][:, 1] = ~np.array([s.inside for s in sels], dtype=bool)
    blocks["skirt"][:, 0] = constants[:, 9] - eye[2] - 1.0 - 0.01 * constants[:, 3:5].max(axis=1)  # below zmin
    return blocks


def tile_blocks(
    hf, view, items, skirts: dict | None = None, culling: bool = True, unit_spacing: bool = False
) -> np.ndarray:
    """The blocks of a frame's (gpu, tile, selected) items, built as arrays over all items (``static_blocks`` and
    ``view_fields``); ``unit_spacing`` for meshes whose positions are metres."""
    if not len(items):
        return np.zeros(0, BLOCK)
    constants = np.stack([tile_constants(t) for _, t, _ in items])
    return view_fields(
        static_blocks(hf, constants, unit_spacing), view, constants, [s for _, _, s in items], skirts, culling
    )


class TileBlocks:
    """The buffer holding a frame's tile blocks (grown as needed): a uniform block per draw, storage for the
    selection, instanced attributes for a multi-draw."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.buffer = ctx.buffer(reserve=BLOCK_BYTES * 16)
        self.version = 0  # counts reallocations (vertex arrays over the buffer are stale then)

    def write(self, blocks: np.ndarray) -> None:
        """Upload a frame's blocks."""
        need = max(len(blocks), 1) * BLOCK_BYTES
        if self.buffer.size < need:
            self.buffer.release()
            self.buffer = self.ctx.buffer(reserve=need)
            self.version += 1
        if len(blocks):
            self.buffer.write(blocks.tobytes())

    def bind(self, i: int) -> None:
        """Make tile i's block the TileBlock of every program (``TILE_BLOCK_BINDING``)."""
        self.buffer.bind_to_uniform_block(TILE_BLOCK_BINDING, offset=i * BLOCK_BYTES, size=BLOCK_BYTES)

    @property
    def nbytes(self) -> int:
        """Bytes of the uniform buffer."""
        return int(self.buffer.size)

    def release(self) -> None:
        """Free the buffer."""
        self.buffer.release()
