"""Windows of a tile store's node arrays read through their decoded chunks, kept in a byte-bounded LRU: what a periodic
extension (``hybrid.tiles.periodic_nodes``) reads of its source's arrays, a few small chunks many times over. Levels
of at most ``WHOLE_BYTES`` (the coarser ones, whose chunks are small and many) are decoded whole once and indexed
directly: a cut gathers rows and columns from them in one indexing, not one window per chunk."""

from __future__ import annotations

import numpy as np

from hybrid.terrain.store_chunks import chunk_reader

from .byte_lru import ByteLRU

CHUNK_BYTES = 64 << 20  # decoded chunks of the source's node arrays kept (``SourceChunks``)
WHOLE_BYTES = 1 << 20  # a source level up to this size is decoded whole once and kept: a window is a slice


def _runs(u: np.ndarray) -> list[tuple[int, int, int, int]]:
    """Runs of consecutive integers in a sorted unique array: (first, stop, position, position stop)."""
    cut = np.nonzero(np.diff(u) != 1)[0] + 1
    starts, stops = np.r_[0, cut], np.r_[cut, len(u)]
    return [(int(u[a]), int(u[b - 1]) + 1, int(a), int(b)) for a, b in zip(starts, stops)]


def gather(read, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """arr[rows x cols] (float32) of a 2-D array, read as a few rectangular windows: ``read(r0, r1, c0, c1)``."""
    ur, ir = np.unique(rows, return_inverse=True)
    uc, ic = np.unique(cols, return_inverse=True)
    block = np.empty((len(ur), len(uc)), np.float32)
    for r0, r1, a0, a1 in _runs(ur):
        for c0, c1, b0, b1 in _runs(uc):
            block[a0:a1, b0:b1] = read(r0, r1, c0, c1)
    return block[np.ix_(ir.ravel(), ic.ravel())]


class SourceChunks:
    """Windows of the source store's node arrays (float32 metres), served from their decoded chunks, each read
    once and kept, least recent out past ``budget`` bytes: a block cut near a seam reads the same few chunks for
    every local level, kind and tightening level, and neighbouring cuts share them. Thread-safe (a loader thread
    cuts blocks ahead of the renderer)."""

    def __init__(self, group, budget: int = CHUNK_BYTES):
        self.group = group
        self._arrays: dict = {}
        self._readers: dict = {}
        self.chunks = ByteLRU(budget)  # decoded chunks by (kind, g, chunk row, chunk column)
        self._whole: dict = {}  # (kind, g) -> the whole level (float32), or None where it is over WHOLE_BYTES

    def array(self, kind: str, g: int):
        """The source's array of a kind at global level g (its handle looked up once)."""
        key = (kind, g)
        if key not in self._arrays:
            self._arrays[key] = self.group[f"nodes/{kind}/{g}"]
        return self._arrays[key]

    def _read(self, kind: str, g: int):
        """The chunk reader of a kind's level-g array (made once)."""
        key = (kind, g)
        if key not in self._readers:
            arr = self.array(kind, g)
            ch, cw = arr.chunks
            self._readers[key] = chunk_reader(arr, (int(ch), int(cw)))
        return self._readers[key]

    def whole(self, kind: str, g: int) -> np.ndarray | None:
        """A kind's level-g array whole (float32, decoded once), or None where it is larger than WHOLE_BYTES."""
        key = (kind, g)
        if key not in self._whole:  # (two threads may both decode it: the same values)
            arr = self.array(kind, g)
            rows, cols = (int(v) for v in arr.shape)
            out = None
            if rows * cols * 4 <= WHOLE_BYTES:
                read, (ch, cw) = self._read(kind, g), arr.chunks
                out = np.empty((rows, cols), np.float32)
                for cy in range(-(-rows // ch)):
                    for cx in range(-(-cols // cw)):
                        out[cy * ch : (cy + 1) * ch, cx * cw : (cx + 1) * cw] = read(cy, cx)
            self._whole[key] = out
        return self._whole[key]

    def gather(self, kind: str, g: int, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """A kind's level-g array at rows x cols (float32): indexed in the whole level where it is kept, else read
        as a few windows (``gather``)."""
        whole = self.whole(kind, g)
        if whole is not None:
            return whole[np.ix_(rows, cols)]
        return gather(self.reader(kind, g), rows, cols)

    def _chunk(self, kind: str, g: int, cy: int, cx: int) -> np.ndarray:
        """Chunk (cy, cx) of a kind's level-g array (float32), its file decoded directly where its layout allows
        (``hybrid.terrain.store_chunks``: the same values as Zarr's read, without its per-call overhead)."""
        read = self._read(kind, g)
        return self.chunks.get((kind, g, cy, cx), lambda: np.asarray(read(cy, cx), dtype=np.float32))

    def window(self, kind: str, g: int, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        """Rows r0..r1-1, columns c0..c1-1 (inside the array) of a kind's level-g array (float32)."""
        ch, cw = self.array(kind, g).chunks
        out = np.empty((r1 - r0, c1 - c0), np.float32)
        for cy in range(r0 // ch, (r1 - 1) // ch + 1):
            ya, yb = max(r0, cy * ch), min(r1, (cy + 1) * ch)
            for cx in range(c0 // cw, (c1 - 1) // cw + 1):
                xa, xb = max(c0, cx * cw), min(c1, (cx + 1) * cw)
                c = self._chunk(kind, g, cy, cx)
                out[ya - r0 : yb - r0, xa - c0 : xb - c0] = c[ya - cy * ch : yb - cy * ch, xa - cx * cw : xb - cx * cw]
        return out

    def reader(self, kind: str, g: int):
        """``read(r0, r1, c0, c1)`` of a kind's level-g array, for ``gather``."""
        return lambda r0, r1, c0, c1: self.window(kind, g, r0, r1, c0, c1)
