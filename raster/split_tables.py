"""Tables of split counts by threshold: a tile's small-node errors, binned once, so that the triangle estimate
(``raster.estimate``) counts a block's nodes whose error exceeds a threshold with one look-up."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BIN_SHIFT = 18  # float32 bits below the bin: 32 bins an octave, 1.6-3.1 % apart
TABLE_BINS = 640  # a tile's tables span 20 octaves up to its largest error


def _bins(x: np.ndarray, nearest: bool = False) -> np.ndarray:
    """Bin of each value >= 0 (metres), int64: its float32 bits without the lowest ``BIN_SHIFT`` (the bins' lower
    edges are the float32 values with those bits zero: 32 an octave, in equal steps within it); with ``nearest``,
    the bin whose lower edge is nearest the value."""
    bits = x.astype(np.float32).view(np.int32).astype(np.int64)
    return (bits + (1 << (BIN_SHIFT - 1)) if nearest else bits) >> BIN_SHIFT


def split_tables(errors: list[np.ndarray]) -> tuple[int, np.ndarray]:
    """(base bin, (kinds, blocks, ``TABLE_BINS``) int64 table) of a tile's small-node errors, one (blocks, nodes)
    array (metres) per kind (``raster.tile_nodes.KINDS``): entry i of a block's row counts its nodes whose error,
    rounded to the nearest bin edge, is at least the edge of bin base + 1 + i, so that for a threshold t in bin
    j = base + i (``raster.estimate_loops.block_splits``) it counts the nodes whose rounded error exceeds t. An error <= 0 never splits
    and is not counted; one more than 20 octaves below the tile's largest is counted as that floor (only a
    threshold below it sees the difference)."""
    nb = errors[0].shape[0]
    rounded = [_bins(np.maximum(e, 0.0), nearest=True) for e in errors]
    positive = [e > 0 for e in errors]
    top = max((int(r[p].max()) for r, p in zip(rounded, positive) if p.any()), default=0)
    low = top + 2 - TABLE_BINS  # the table's first bin; its last counts nothing
    hist = np.stack(
        [
            np.bincount((np.arange(nb)[:, None] * TABLE_BINS + np.maximum(r - low, 0))[p], minlength=nb * TABLE_BINS)
            for r, p in zip(rounded, positive)
        ]
    )
    return low - 1, np.cumsum(hist.reshape(-1, nb, TABLE_BINS)[..., ::-1], axis=-1)[..., ::-1]


@dataclass(frozen=True)
class SplitTables:
    """Stacked tiles' ``split_tables``: per row (tile) its base bin (rows,) and its tables (rows, kinds, blocks,
    ``TABLE_BINS``), looked up by flat index."""

    base: np.ndarray
    tables: np.ndarray

    @property
    def blocks(self) -> int:
        """Blocks a tile."""
        return self.tables.shape[2]
