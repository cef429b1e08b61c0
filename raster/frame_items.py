"""The per-item buffers of a frame's leaf selection: every tile drawing of the frame (an item) gets its draw
commands, its leaf list and its skirt segments in one shared buffer each, and both passes' work tables lie in
one more, so the selection is one dispatch a pass over all items (select.comp.glsl).

Control (CONTROL_WORDS a item, at item * CONTROL_WORDS): the points, template and skirt indirect commands
(moderngl's 5-word stride, so item i's command c is command 4 i + c of the buffer), then the item's arena base,
its pass-0 work groups done, its pass-0 work groups and its leaf count. Work: pass 1's indirect dispatch (x, 1, 1) and an unused
word, pass 0's table (one word a work group: item | group << 16, written here), then pass 1's (written by pass 0
as each item's leaves are counted). Buffers grow to the frame's needs and are kept; ``version`` counts
reallocations of the segment buffer (vertex arrays over it are stale when it changed).
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import gl_bytes

CONTROL_WORDS = 20  # control words a item
COMMANDS_PER_ITEM = CONTROL_WORDS // 5
BASE_WORD, DONE_WORD, GROUPS_WORD, FOUND_WORD = 15, 16, 17, 18
CMD_POINTS, CMD_TEMPLATE, CMD_SKIRTS = 0, 1, 2
SEGMENT_WORDS = 6  # skirt segment: x, y, height of both ends
WORK_HEADER = 4  # pass 1's dispatch (x, y, z) and an unused word
LOCAL = 64  # work group size (select.comp.glsl)
MAX_ITEMS = 1 << 16  # items and work groups per item a work-table word can name
CONTROL_BINDING, SEGMENTS_BINDING, FOUND_BINDING, WORK_BINDING = 2, 3, 6, 10  # storage bindings
ITEM_DEFINES = {
    "CONTROL_WORDS": CONTROL_WORDS,
    "BASE_WORD": BASE_WORD,
    "DONE_WORD": DONE_WORD,
    "GROUPS_WORD": GROUPS_WORD,
    "FOUND_WORD": FOUND_WORD,
    "CMD_POINTS_": CMD_POINTS,
    "CMD_TEMPLATE_": CMD_TEMPLATE,
    "WORK_HEADER": f"{WORK_HEADER}u",
    "LOCAL": LOCAL,
    "SEGMENT_WORDS": SEGMENT_WORDS,
    "CONTROL_BINDING": CONTROL_BINDING,
    "SEGMENTS_BINDING": SEGMENTS_BINDING,
    "FOUND_BINDING": FOUND_BINDING,
    "WORK_BINDING": WORK_BINDING,
}
"""The layout above as select.comp.glsl's defines: the shader's only source of these numbers."""


def found_words(n: int) -> int:
    """Words of one n-cell item's leaf list: room for every leaf ((n / 2)² at most)."""
    return (n // 2) ** 2


def segment_words(n: int) -> int:
    """Words of one n-cell item's skirt segments: two a tile cell along its edge at most."""
    return max(4 * n, 8) * SEGMENT_WORDS


def control_blank(groups0: np.ndarray, segment_base: np.ndarray) -> np.ndarray:
    """Control words (items * CONTROL_WORDS,) before selection: instance counts 1, the counts the selection
    fills in (draws, leaves) 0, each skirt command's first instance at its item's segments, each item's pass-0 work groups."""
    words = np.zeros((len(groups0), CONTROL_WORDS), np.uint32)
    words[:, 5 * CMD_POINTS + 1] = 1  # leaf points: one instance of (leaf count) points
    words[:, 5 * CMD_TEMPLATE + 1] = 1  # mesh: one instance of (24 x leaf count) indices,
    words[:, 5 * CMD_TEMPLATE + 4] = np.arange(len(groups0))  # its base instance the item (raster.indexed)
    words[:, 5 * CMD_SKIRTS] = 6  # skirts: (segment count) instances of a 6-vertex quad
    words[:, 5 * CMD_SKIRTS + 3] = np.asarray(segment_base) // SEGMENT_WORDS  # first instance
    words[:, GROUPS_WORD] = groups0
    return words.reshape(-1)


def work_table(groups0: np.ndarray) -> np.ndarray:
    """Pass 0's work table: for each item, one word per work group (item | group << 16)."""
    groups0 = np.asarray(groups0, dtype=np.int64)
    if len(groups0) > MAX_ITEMS or (len(groups0) and groups0.max() > MAX_ITEMS):
        raise TerrabenchError(
            f"a frame's leaf selection handles at most {MAX_ITEMS} tiles of at most "
            f"{MAX_ITEMS * LOCAL} nodes each, got {len(groups0)} tiles"
        )
    item = np.repeat(np.arange(len(groups0)), groups0)
    group = np.arange(len(item)) - np.repeat(np.cumsum(groups0) - groups0, groups0)
    return (item | (group << 16)).astype(np.uint32)


class FrameItems:
    """The shared per-item buffers of a strategy's selection, grown as frames need."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.control = ctx.buffer(reserve=CONTROL_WORDS * 4 * 16)
        self.found = ctx.buffer(reserve=4 * 4096)
        self.segments = ctx.buffer(reserve=4 * 4096)
        self.work = ctx.buffer(reserve=4 * 4096)
        self.version = 0

    def _fit(self, name: str, nbytes: int) -> bool:
        """Make buffer ``name`` hold at least nbytes (twice that when remade); True if remade."""
        buf = getattr(self, name)
        if buf.size >= nbytes:
            return False
        buf.release()
        setattr(self, name, self.ctx.buffer(reserve=2 * nbytes))
        return True

    def prepare(self, n: int, groups0: np.ndarray, arena_capacity: int):
        """Size and fill the buffers for a frame's items (all of n cells a side, pass-0 work groups ``groups0``);
        (found base, segment base) words per item, and where pass 1's table starts in the work buffer."""
        items = len(groups0)
        found_base = np.arange(items, dtype=np.int64) * found_words(int(n))
        seg_base = np.arange(items, dtype=np.int64) * segment_words(int(n))
        table0 = work_table(groups0)
        table1_start = WORK_HEADER + len(table0)
        table1 = -(-int(arena_capacity) // LOCAL) + items  # pass 1's groups at most
        self._fit("control", max(items, 1) * CONTROL_WORDS * 4)
        self._fit("found", max(items * found_words(int(n)), 1) * 4)
        if self._fit("segments", max(items * segment_words(int(n)), 1) * 4):
            self.version += 1
        self._fit("work", (table1_start + table1) * 4)
        self.control.write(control_blank(groups0, seg_base).tobytes())
        self.work.write(np.concatenate([np.array([0, 1, 1, 0], np.uint32), table0]).tobytes())
        return found_base, seg_base, table1_start

    def bind(self) -> None:
        """Bind the buffers where the selection reads and writes them (``*_BINDING``)."""
        self.control.bind_to_storage_buffer(CONTROL_BINDING)
        self.segments.bind_to_storage_buffer(SEGMENTS_BINDING)
        self.found.bind_to_storage_buffer(FOUND_BINDING)
        self.work.bind_to_storage_buffer(WORK_BINDING)

    @property
    def nbytes(self) -> int:
        """GPU bytes of the buffers, as the driver reports them."""
        return gl_bytes(self.control, self.found, self.segments, self.work)

    def release(self) -> None:
        """Free the buffers."""
        for b in (self.control, self.found, self.segments, self.work):
            b.release()
