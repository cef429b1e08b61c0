"""Per-tile node blocks: the raster strategies' node data of one pyramid tile in the layout its upload sends to
the GPU, and a tile store's copy of them, one chunk a tile (``nodes/blocks/<level>``).

A tile of n cells at pyramid level l holds, for each local level m (nodes of 2^(m+1) tile cells, global level
l + m of the node arrays), its (n >> (m+1))² nodes with a one-node apron on every side, row by row from the
south: columns E (effective error, metres), zlo, zhi (box height range, metres above the origin z) and inside
(0 for an apron node beyond the node square; inside it 1 plus the node's side error codes,
``hybrid.tiles.sidecodes``, or 1 in a store prepared before they were). Cut from the store's node arrays
(``hybrid.tiles.store_nodes``), a block needs one read per local level and array, each of a window that
spans many small chunks; the stored blocks make a tile's upload one read of one chunk.
"""

from __future__ import annotations

import numpy as np

from .sidecodes import stored_codes

COLUMNS = 4  # E, zlo, zhi, inside
WINDOW_BYTES = 8 << 20  # rows of a node array read at once while building blocks, per array


class RowWindows:
    """A 2-D array read a window of whole rows at a time (up to ``WINDOW_BYTES``), for row-ordered readers that
    ask for overlapping windows: each stored chunk is decoded about once instead of once per window asked."""

    def __init__(self, array):
        self.array, self.shape = array, tuple(int(s) for s in array.shape)
        self.rows = max(1, WINDOW_BYTES // max(1, self.shape[1] * np.dtype(array.dtype).itemsize))
        self.r0, self.held = 0, np.empty((0, self.shape[1]), array.dtype)

    def __getitem__(self, window: tuple[slice, slice]) -> np.ndarray:
        """The samples of ``window`` (row and column slices with non-negative bounds and step 1)."""
        rs, cs = window
        ra, rb = rs.start or 0, self.shape[0] if rs.stop is None else min(rs.stop, self.shape[0])
        if ra < self.r0 or rb > self.r0 + self.held.shape[0]:
            self.r0 = ra
            self.held = np.asarray(self.array[ra : min(self.shape[0], max(rb, ra + self.rows)), :])
        return self.held[ra - self.r0 : rb - self.r0, cs]


def block_offsets(n: int) -> np.ndarray:
    """Start of each local level's apron grid in an n-cell tile's block, and the block's length (nodes)."""
    sides = [(n >> (m + 1)) + 2 for m in range(int(np.log2(n)))]
    return np.concatenate([[0], np.cumsum(np.square(sides))]).astype(np.int32)


def band_blocks(effective, zlo, zhi, level: int, ty: int, n: int, tx0: int, tx1: int, inside=None) -> np.ndarray:
    """Blocks (tx1 - tx0, nodes, 4) float32 of the level-``level`` tiles tx0..tx1-1 of tile row ty, from the
    node arrays by global level (numpy or Zarr arrays: one window read per local level and array); ``inside``:
    arrays by global level of the fourth column's value inside the node square (None: 1)."""
    count = tx1 - tx0
    parts = []
    for m in range(int(np.log2(n))):
        g = level + m
        side = n >> (m + 1)
        total = effective[g].shape[0]
        r0, c0 = ty * side - 1, tx0 * side - 1
        width = count * side + 2
        ra, rb = max(r0, 0), min(r0 + side + 2, total)
        ca, cb = max(c0, 0), min(c0 + width, total)
        band = np.zeros((side + 2, width, COLUMNS), np.float32)
        win = (slice(ra - r0, rb - r0), slice(ca - c0, cb - c0))
        if rb > ra and cb > ca:
            for k, arr in enumerate((effective[g], zlo[g], zhi[g])):
                band[win + (k,)] = np.asarray(arr[ra:rb, ca:cb])
            band[win + (3,)] = 1.0 if inside is None else np.asarray(inside[g][ra:rb, ca:cb])
        # each tile's window of side + 2 columns starts every side columns
        tiles = np.lib.stride_tricks.sliding_window_view(band, side + 2, axis=1)[:, ::side]
        parts.append(tiles.transpose(1, 0, 3, 2).reshape(count, (side + 2) ** 2, COLUMNS))
    return np.ascontiguousarray(np.concatenate(parts, axis=1), dtype=np.float32)


def build_blocks(g, n: int, max_level: int, mark) -> None:
    """Write ``nodes/blocks/<level>`` (tiles y, tiles x, nodes, 4) of a store group whose node arrays are written,
    one chunk a tile, a tile row a band; ``mark(key, count, what)`` records each band (and may interrupt)."""
    levels = int(dict(g.attrs["nodes"])["levels"])
    effective, zlo, zhi = (
        tuple(RowWindows(g[f"nodes/{k}/{lev}"]) for lev in range(levels)) for k in ("effective", "zlo", "zhi")
    )
    codes = stored_codes(g, levels)
    codes = None if codes is None else tuple(RowWindows(c) for c in codes)
    length = int(block_offsets(n)[-1])
    for level in range(max_level + 1):
        ty_n, tx_n = g[f"zmin/{level}"].shape
        name = f"nodes/blocks/{level}"
        out = (
            g[name]
            if name in g
            else g.create_array(
                name, shape=(ty_n, tx_n, length, COLUMNS), chunks=(1, 1, length, COLUMNS), dtype="f4", fill_value=0.0
            )
        )
        key = f"blocks:{level}"
        for ty in range(int(dict(g.attrs["progress"]).get(key, 0)), ty_n):
            out[ty] = band_blocks(effective, zlo, zhi, level, ty, n, 0, tx_n, codes)
            mark(key, ty + 1, f"node blocks, level {level} row {ty + 1}")
    g.attrs.update({"node_blocks": True})
