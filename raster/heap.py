"""Resident tiles' heights and node data in two shared GPU buffers per cell count, one fixed-size slot a tile.

The leaf selection (select.comp.glsl) runs as one dispatch over every tile of a frame, so it cannot bind a
tile's own buffers: each tile's data lies in a slot of its cell count's heap instead, and the tile's block
carries where (raster.tileblock). A heap grows by doubling (a GPU copy of the used slots), and when eviction
leaves it under a quarter full it is made again for twice what it holds, its tiles moved down to the first
slots. A heap may be made with a floor of slots (``min_slots``: a renderer's GPU budget of tiles, as a streaming
tile pool is sized): it starts there and never shrinks below, so that no growth, whose allocation costs a
software rasterizer about 0.4 ms a MB, lands in a frame. Bytes: a tile counts its slot's; what the heaps hold
unused is shared (``spare_nbytes``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from hybrid.gl.context import gl_bytes

if TYPE_CHECKING:
    import moderngl

NODES_BINDING, HEIGHTS_BINDING = 0, 5  # storage bindings
HEAP_DEFINES = {"NODES_BINDING": NODES_BINDING, "HEIGHTS_BINDING": HEIGHTS_BINDING}
"""The heap's bindings as select.comp.glsl's defines."""

MIN_SLOTS = 4  # smallest heap, tiles
SHRINK_BELOW = 0.25  # remake a heap whose tiles fill less than this share of it ...


def slot_bytes(n: int, node_rows: int) -> int:
    """GPU bytes of one n-cell tile's heap slot: its (n+1)² float32 heights and ``node_rows`` vec4 node rows."""
    return 4 * (int(n) + 1) ** 2 + 16 * int(node_rows)


class HeapSlot:
    """Where one tile's data lies in its heap; ``index`` changes when the heap is compacted."""

    __slots__ = ("heap", "index")

    def __init__(self, heap: TileHeap, index: int):
        self.heap, self.index = heap, index

    @property
    def heights_base(self) -> int:
        """First float of the tile's heights in the heights buffer."""
        return self.index * self.heap.height_words

    @property
    def nodes_base(self) -> int:
        """First vec4 of the tile's nodes in the node buffer."""
        return self.index * self.heap.node_rows

    @property
    def nbytes(self) -> int:
        """GPU bytes of the slot (heights and nodes)."""
        return self.heap.slot_bytes

    def release(self) -> None:
        """Give the slot back to its heap."""
        self.heap.free(self)


class TileHeap:
    """Heights ((n+1)² float32) and node rows (``node_rows`` vec4) of every resident n-cell tile of a strategy."""

    def __init__(self, ctx, n: int, node_rows: int, min_slots: int = MIN_SLOTS):
        self.ctx, self.n, self.node_rows = ctx, int(n), int(node_rows)
        self.min_slots = max(int(min_slots), MIN_SLOTS)
        self.height_words = (self.n + 1) ** 2
        self.slot_bytes = slot_bytes(self.n, self.node_rows)
        self.capacity = 0
        self.heights: moderngl.Buffer | None = None  # None once released
        self.nodes: moderngl.Buffer | None = None
        self.owners: list[HeapSlot | None] = []
        self._remake(self.min_slots)

    def _copy(self, src: int, dst: int, heights, nodes) -> None:
        """GPU copy of slot ``src`` of the current buffers to slot ``dst`` of ``heights`` and ``nodes``."""
        hb, nb = 4 * self.height_words, 16 * self.node_rows
        self.ctx.copy_buffer(heights, self.heights, hb, read_offset=src * hb, write_offset=dst * hb)
        self.ctx.copy_buffer(nodes, self.nodes, nb, read_offset=src * nb, write_offset=dst * nb)

    def alloc(self, heights: np.ndarray, nodes: np.ndarray) -> HeapSlot:
        """A slot holding one tile's heights ((n+1)² float32) and node rows ((node_rows, 4) float32)."""
        if heights.size != self.height_words or nodes.shape != (self.node_rows, 4):
            raise ValueError(
                f"a {self.n}-cell tile's heap slot holds {self.height_words} heights and "
                f"{self.node_rows} node rows, got {heights.size} and {nodes.shape[0]}"
            )
        if None in self.owners:  # the first free slot (list.index: one C-speed scan)
            index = self.owners.index(None)
        else:  # full: its tiles keep their slots in a heap twice the size
            index = self.capacity
            self._remake(2 * self.capacity)
        slot = HeapSlot(self, index)
        self.owners[slot.index] = slot
        assert self.heights is not None and self.nodes is not None  # _remake made them; not released
        # written from the arrays' own memory (a buffer, not a bytes copy)
        self.heights.write(np.ascontiguousarray(heights, dtype=np.float32), offset=slot.heights_base * 4)
        self.nodes.write(np.ascontiguousarray(nodes, dtype=np.float32), offset=slot.nodes_base * 16)
        return slot

    def free(self, slot: HeapSlot) -> None:
        """Give a slot back; a heap left under SHRINK_BELOW full is remade for twice its tiles (at least
        ``min_slots``), its tiles moved to the first slots."""
        if slot.index >= len(self.owners) or self.owners[slot.index] is not slot:
            return
        self.owners[slot.index] = None
        used = self.used
        if self.capacity > self.min_slots and used < SHRINK_BELOW * self.capacity:
            self._remake(max(self.min_slots, 2 * used))

    def _remake(self, capacity: int) -> None:
        """Make the buffers again for ``capacity`` slots, the used slots copied to the first ones in slot order
        (their indices updated; a full heap's keep theirs)."""
        used = [s for s in self.owners if s is not None]
        heights = self.ctx.buffer(reserve=capacity * 4 * self.height_words)
        nodes = self.ctx.buffer(reserve=capacity * 16 * self.node_rows)
        for i, s in enumerate(used):
            self._copy(s.index, i, heights, nodes)
            s.index = i
        self._free_buffers()
        self.heights, self.nodes, self.capacity = heights, nodes, capacity
        self.owners = used + [None] * (capacity - len(used))

    def bases(self, slots) -> tuple[np.ndarray, np.ndarray]:
        """(nodes_base, heights_base) of the heap's slots as (len(slots),) arrays (``HeapSlot``'s, at once)."""
        index = np.array([s.index for s in slots], dtype=np.int64)
        return index * self.node_rows, index * self.height_words

    @property
    def used(self) -> int:
        """Slots holding a tile."""
        return len(self.owners) - self.owners.count(None)

    @property
    def spare_nbytes(self) -> int:
        """GPU bytes of the heap's buffers (as the driver reports them) less its tiles' slots."""
        return gl_bytes(self.heights, self.nodes) - self.used * self.slot_bytes

    def bind(self) -> None:
        """Bind the node buffer and the heights at their storage bindings (``HEAP_DEFINES``)."""
        assert self.heights is not None and self.nodes is not None  # bound only while the heap is in use
        self.nodes.bind_to_storage_buffer(NODES_BINDING)
        self.heights.bind_to_storage_buffer(HEIGHTS_BINDING)

    def _free_buffers(self) -> None:
        for b in (self.heights, self.nodes):
            if b is not None:
                b.release()
        self.heights = self.nodes = None

    def release(self) -> None:
        """Free the buffers (the slots still handed out become invalid)."""
        self._free_buffers()
        self.owners = []
        self.capacity = 0
