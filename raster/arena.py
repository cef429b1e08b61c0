"""The frame's leaf arena of a tilelet strategy: one set of output buffers that every raster tile of a frame
writes its selected leaves into, sized by what the view selects rather than by what a tile could hold.

The GPU selection (select.comp.glsl) reserves each tile's leaves in the arena once its listing pass knows
their count; a tile whose leaves do not fit draws nothing and is counted as overflow, and the strategy then
grows the arena and draws the frame again (raster.tilelets), so no frame it returns misses a leaf. Between
draw calls the arena is made again for twice the last call's leaves when they filled over three quarters of it
(so that a frame rarely overflows), and for twice the largest of 64 calls in a row that all filled under a
quarter of it (single tiles drawn by a timing pass do not shrink it under the frames around them). A call with
more tiles than the last is sized ahead for them, so that it fits where it overflowed and was drawn twice: at the
leaves a tile of the last call of several tiles (a camera jump), or before any such call at one leaf per
``PIXELS_PER_LEAF`` pixels of the view and at most ``TILE_LEAVES`` a tile (a flight's first frame after a warm-up
of one tile; the cap keeps a mixed frame's few raster tiles from sizing it for the whole view). A size so guessed
that the call then fills under SHRINK_BELOW is made again for that call's leaves before the next. Capacity is in
leaves: a leaf is one 13-word record (geometry-shader path) or 9 vertices and 24 indices (indexed path); with
lean full-resolution leaves (``full_res`` "lean", raster.tilelets) a 15-word record (the SE and NW cells' turns
added) or 11 vertices and 36 indices (their centre posts and 4 triangles each).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from hybrid.gl.context import gl_bytes

if TYPE_CHECKING:
    import moderngl

MIN_LEAVES = 4096  # smallest arena, leaves
GROW = 2.0  # a grown or shrunk arena holds this many times the frame's leaves
GROW_ABOVE = 0.75  # grow before the next frame when the frame's leaves fill more than this share
SHRINK_BELOW = 0.25  # shrink when the calls' leaves fill less than this share ...
SHRINK_AFTER = 64  # ... in this many draw calls in a row
PIXELS_PER_LEAF = 16  # the first call of several tiles is sized for one leaf per this many pixels of its view ...
TILE_LEAVES = 256  # ... and at most this many leaves a tile
LEAF_SIZES = {"exact": (13, 9, 24), "lean": (15, 11, 36)}
"""A leaf's (record words (raster.selection.LEAF_FORMAT), vec4 vertices, indices) by full-resolution rule."""
LAYOUTS = {rule: (words * 4, vertices * 16, indices * 4) for rule, (words, vertices, indices) in LEAF_SIZES.items()}
"""Bytes a leaf of (record, vertices, indices) by full-resolution rule."""
RECORDS_BINDING, VERTICES_BINDING, INDICES_BINDING = 1, 7, 8  # storage bindings


def arena_defines(full_res: str) -> dict:
    """The arena's layout and bindings as select.comp.glsl's defines, for a full-resolution rule."""
    words, vertices, indices = LEAF_SIZES[full_res]
    return {
        "LEAF_RECORD_WORDS": f"{words}u",
        "LEAF_VERTICES": f"{vertices}u",
        "LEAF_INDICES": f"{indices}u",
        "RECORDS_BINDING": RECORDS_BINDING,
        "VERTICES_BINDING": VERTICES_BINDING,
        "INDICES_BINDING": INDICES_BINDING,
    }


def arena_leaves(need: int) -> int:
    """Capacity (leaves) of an arena made for ``need`` leaves: GROW times it, whole 1024s, at least MIN_LEAVES."""
    return max(MIN_LEAVES, -(-int(np.ceil(need * GROW)) // 1024) * 1024)


class LeafArena:
    """Output buffers shared by a frame's raster tiles; ``writes`` is "records" or "mesh", ``full_res`` the leaves'
    layout (``LAYOUTS``; "exact" until ``use_layout``). ``version`` counts allocations: vertex arrays made over the
    buffers are stale when it has changed."""

    def __init__(self, ctx, writes: str, capacity: int = MIN_LEAVES, ahead: bool = True):
        self.ctx, self.writes, self.full_res = ctx, writes, "exact"
        self.items, self.rate, self.ahead = 1, 0.0, bool(ahead)  # the last call's tiles; leaves a tile; sized ahead
        self.guessed = False  # the size was guessed before any call of several tiles
        self.capacity = 0
        self.records: moderngl.Buffer | None = None  # the buffers are None once released
        self.vertices: moderngl.Buffer | None = None
        self.indices: moderngl.Buffer | None = None
        self.version = 0
        self.last = self.sparse = self.sparse_peak = 0
        self._allocate(int(capacity))

    def _allocate(self, capacity: int) -> None:
        self._free()
        mesh = self.writes == "mesh"  # only the output the strategy's draw reads is allocated
        self.capacity = capacity
        record, vertex, index = self.leaf_bytes
        self.records = self.ctx.buffer(reserve=(1 if mesh else capacity) * record)
        self.vertices = self.ctx.buffer(reserve=(capacity if mesh else 1) * vertex)
        self.indices = self.ctx.buffer(reserve=(capacity if mesh else 1) * index)
        self.version += 1

    @property
    def leaf_bytes(self) -> tuple[int, int, int]:
        """Bytes a leaf takes of (records, vertices, indices) in this arena's layout."""
        return LAYOUTS[self.full_res]

    def use_layout(self, full_res: str) -> None:
        """Hold leaves laid out for the full-resolution rule ``full_res`` (made again, same capacity, on a change)."""
        if full_res != self.full_res:
            self.full_res = full_res
            self._allocate(self.capacity)

    def note(self, leaves: int, items: int = 1) -> None:
        """Record a draw call's leaves and tiles (every call: whole frames, and the single tiles a timing pass
        draws; only calls of several tiles set the leaves a tile)."""
        self.last, self.items = int(leaves), max(int(items), 1)
        if self.items > 1:
            self.rate = self.last / self.items
        if self.last < SHRINK_BELOW * self.capacity and self.capacity > MIN_LEAVES:
            self.sparse += 1
            self.sparse_peak = max(self.sparse_peak, self.last)
        else:
            self.sparse, self.sparse_peak = 0, 0

    def prepare(self, items: int = 1, pixels: int = 0) -> bool:
        """Before a draw call of ``items`` tiles into a view of ``pixels`` pixels: grow for the leaves expected (the
        last call's; for more tiles than it had, their count at the leaves a tile, or before any call of several
        tiles one a PIXELS_PER_LEAF pixels, TILE_LEAVES a tile at most) if they fill over GROW_ABOVE of the arena;
        shrink for the last call's leaves where a guessed size held under SHRINK_BELOW of them, or for the largest
        of a run of SHRINK_AFTER calls that all filled under SHRINK_BELOW; True if remade."""
        need = self.last
        if self.guessed and self.rate:  # the guess met its first call of several tiles: keep what it needed
            self.guessed = False
            if need < SHRINK_BELOW * self.capacity:
                return self.remake(need)
        if self.ahead and items > self.items:
            guess = items * self.rate if self.rate else min(pixels / PIXELS_PER_LEAF, items * TILE_LEAVES)
            need = max(need, int(np.ceil(guess)))
            if need > GROW_ABOVE * self.capacity and not self.rate:
                self.guessed = True
        if need > GROW_ABOVE * self.capacity:
            return self.remake(need)
        if self.sparse >= SHRINK_AFTER:
            return self.remake(self.sparse_peak)
        return False

    def remake(self, leaves: int) -> bool:
        """Make the arena again for ``leaves`` leaves (GROW times them); True if the buffers were replaced."""
        self.sparse, self.sparse_peak = 0, 0
        new = arena_leaves(leaves)
        if new == self.capacity:
            return False
        self._allocate(new)
        return True

    def bind(self) -> None:
        """Bind the buffers where the selection writes them (``*_BINDING``)."""
        assert self.records is not None and self.vertices is not None and self.indices is not None  # not released
        self.records.bind_to_storage_buffer(RECORDS_BINDING)
        self.vertices.bind_to_storage_buffer(VERTICES_BINDING)
        self.indices.bind_to_storage_buffer(INDICES_BINDING)

    @property
    def nbytes(self) -> int:
        """GPU bytes of the arena's buffers, as the driver reports them."""
        return gl_bytes(self.records, self.vertices, self.indices)

    def _free(self) -> None:
        for b in (self.records, self.vertices, self.indices):
            if b is not None:
                b.release()
        self.records = self.vertices = self.indices = None

    def release(self) -> None:
        """Free the buffers."""
        self._free()
