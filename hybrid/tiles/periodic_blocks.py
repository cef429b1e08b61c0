"""Per-tile node blocks (``hybrid.tiles.store_blocks``) of a virtual periodic extension (``hybrid.tiles.periodic``).

Away from the seams every node of the extension is its source node's value exactly (``hybrid.tiles.periodic_nodes``:
only nodes at local indices T-2, T-1 and 0 of a period, T nodes a period, may differ), so the block of a tile whose
nodes, apron included, all lie at local indices 1..T-3 of their level is the source tile's block at the same place in
its period: one read of one chunk. Tiles near a seam, tiles of levels whose tiles span a whole period and tiles
reaching over the padding cut their block from the extension's node arrays, window by window. Those arrays repeat
every period away from the extension's first and last period, so a block cut there serves every tile at the same
place in another period: the periodic pattern is cut once. Cut blocks are kept in an LRU bounded in bytes, keyed by
their place in the period (a tile of the first or last period by its own key); cutting is thread-safe, so a store's
loader thread can cut a tile's block ahead of its upload (``PeriodicBlocks.ready`` says whether it still needs to).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .byte_lru import ByteLRU
from .store_blocks import band_blocks

CUT_BYTES = 64 << 20  # bytes of blocks cut near the seams kept, least recent out


def source_block_tile(level: int, tx: int, ty: int, n: int, period: int, cells: int) -> tuple[int, int] | None:
    """(tx, ty) of the source tile whose block equals the extension tile's, or None where it may differ.

    ``period``: the source's cells a side (a power of two, a multiple of n); ``cells``: the extension's cells a
    side. Global node level g = level + m holds T = period >> (g + 1) nodes a period; the tile's nodes at local
    level m, with their one-node apron, are the indices i*side - 1 .. (i + 1)*side of side = n >> (m + 1)."""
    span = n << level
    if span > period:
        return None
    per = period // span  # tiles a period at this level
    sx, sy = tx % per, ty % per
    for m in range(int(np.log2(n))):
        side, g = n >> (m + 1), level + m
        T, inside = period >> (g + 1), cells >> (g + 1)  # nodes a period; nodes over the extension
        for i, a in ((sx, tx), (sy, ty)):
            if i * side - 1 < 1 or (i + 1) * side > T - 3 or (a + 1) * side >= inside:
                return None
    return sx, sy


def period_residue(level: int, tx: int, ty: int, n: int, period: int, cells: int) -> tuple[int, int] | None:
    """Where an extension tile sits in the pattern that repeats every period: (x, y) of its corner modulo the
    period, in tiles, for a tile outside the first and the last period (its block, cut from the extension's
    arrays, is then the same as every such tile's at that place); None for a tile in the first or last period,
    whose nodes may see the extension's edges or padding."""
    span = n << level
    for a in (tx, ty):
        if a * span < period or (a + 1) * span > cells - period:
            return None
    return (tx * span) % period // span, (ty * span) % period // span


class _LevelBlocks:
    """The blocks of one pyramid level, indexed [ty, tx] as a store's ``nodes/blocks/<level>`` array."""

    def __init__(self, owner: PeriodicBlocks, level: int):
        self.owner, self.level = owner, level

    def __getitem__(self, index) -> np.ndarray:
        ty, tx = (int(i) for i in index)
        o = self.owner
        at = source_block_tile(self.level, tx, ty, o.n, o.period, o.cells)
        if at is not None:
            return np.asarray(o.source_blocks[self.level][at[1], at[0]], dtype=np.float32)
        key = o.cut_key(self.level, tx, ty)  # cut before, or a tile at this place in another period
        return o.cut.get(key, lambda: band_blocks(*o.arrays, self.level, ty, o.n, tx, tx + 1, o.codes)[0])


class PeriodicBlocks:
    """Node blocks of an extension by pyramid level: the source's where they are equal, else cut (see module)."""

    def __init__(
        self,
        source_blocks: tuple,
        arrays: tuple[Any, Any, Any],
        n: int,
        period: int,
        cells: int,
        levels: int,
        codes: tuple | None = None,
        budget: int = CUT_BYTES,
    ):
        self.source_blocks, self.arrays, self.codes = source_blocks, arrays, codes
        self.n, self.period, self.cells = int(n), int(period), int(cells)
        self.cut = ByteLRU(budget)  # blocks cut near seams, by ``cut_key``
        self._levels = tuple(_LevelBlocks(self, lev) for lev in range(levels))

    def __getitem__(self, level: int) -> _LevelBlocks:
        return self._levels[level]

    def cut_key(self, level: int, tx: int, ty: int) -> tuple:
        """The key of a cut block in ``cut``: (level, place in the period), or ("tile", level, tx, ty) for a tile
        in the first or last period (its cut block is its own)."""
        residue = period_residue(level, tx, ty, self.n, self.period, self.cells)
        return ("tile", level, tx, ty) if residue is None else (level, *residue)

    def ready(self, level: int, tx: int, ty: int) -> bool:
        """Whether the tile's block is one read (the source's, or cut before), not a cut from the node arrays
        (tens to hundreds of ms a tile near the seams of a large extension)."""
        if source_block_tile(level, tx, ty, self.n, self.period, self.cells) is not None:
            return True
        return self.cut_key(level, tx, ty) in self.cut

    def __len__(self) -> int:
        return len(self._levels)
