"""The CPU part of a raster tile's upload: its node block with a one-node apron (``raster.nodes``) and the block's
per-level extremes (``raster.bounds_loops``), made of the tile's key alone.

A store's loader thread makes it ahead of the upload (``hybrid.uploads.host_jobs``, ``StorePyramid.derive``), so
that the upload on the frame's thread is the heap's writes and a few small arrays: streaming then fits more
uploads in a frame's budget. Without a loader (an in-memory terrain) the upload makes it itself.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .nodes import nodes_for, tile_levels, tile_node_block


@dataclass(frozen=True)
class HostNodes:
    """A tile's node block ``data`` (count, 4) float32 and its ``offsets`` per local level, with each level's
    largest effective error and lowest and highest node bound (float64 metres); ``key`` and ``beta`` say what it was
    made for."""

    key: object
    beta: float
    data: np.ndarray
    offsets: np.ndarray
    err: np.ndarray
    zlo: np.ndarray
    zhi: np.ndarray

    @property
    def nbytes(self) -> int:
        """Host bytes held (what a store's host cache counts)."""
        return sum(int(a.nbytes) for a in (self.data, self.offsets, self.err, self.zlo, self.zhi))


def host_nodes(hf, n: int, beta: float, key) -> HostNodes:
    """The node block and per-level extremes of tile ``key`` (n cells a side) of terrain ``hf`` at ``beta``."""
    from .bounds_loops import level_extremes  # numba: imported on first use, not with the package

    nodes = nodes_for(hf, n, beta)
    data, offsets = tile_node_block(nodes, int(key.level), int(key.tx), int(key.ty), n)
    err, zlo, zhi = level_extremes(np.asarray(data, np.float32), np.asarray(offsets, np.int64), int(n))
    return HostNodes(key, float(beta), data, offsets, err, zlo, zhi)


def bounds_rows(err: np.ndarray, zlo: np.ndarray, zhi: np.ndarray, n: int, spacing_xy: tuple[float, float]):
    """(largest effective error, lower box corners, upper box corners) per local level of an n-cell tile from its
    levels' extremes (tile-local metres; ``spacing_xy`` its (x, y) sample spacing): a level's box grows by its
    node side on every side."""
    sp = np.asarray(spacing_xy, dtype=np.float64)
    grow = (2 << np.arange(len(err)))[:, None] * sp  # (levels, 2): each level's node side, x and y
    return err, np.column_stack([-grow, zlo]), np.column_stack([n * sp + grow, zhi])


@lru_cache(maxsize=16)
def level_starts(n: int) -> np.ndarray:
    """Invocation index of the first node of each local level in the listing pass (levels + 1 entries): level 0
    is listed by its split parents (levels 0 and 1 both start at 0), except in a 2-cell tile. Read-only: shared
    by every tile of n cells."""
    levels = tile_levels(n)
    counts = [0 if levels > 1 else 1] + [(n >> (m + 1)) ** 2 for m in range(1, levels)]
    out = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    out.flags.writeable = False
    return out
