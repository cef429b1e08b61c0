"""A virtual periodic extension of a square tile store to a larger size, as Bhattacharjee et al. extended the
16K Puget map: sample (i, j) of the extension is the source's sample (i mod P, j mod P), P the source's cells a
side, and nothing is written to disk. Its name ends in ``-periodic-<size>`` and its store attributes carry
``periodic``, so every table and report says so.

Tiles that lie inside one period are the source's tiles with the source's bounds and errors. A tile whose last
row or column falls on a seam (where sample P of the source gives way to its sample 0) differs from its source
tile there: its bounds take in the source's first row or column over the same span (the corner sample (0, 0)
included), and its error is bounded by the source tile's error plus twice the largest seam step over its span
(the extension's level-0 samples and its level-l surface each differ from the source's by at most that step).
Coarser levels whose tiles span more than a period repeat the source's pattern: their errors are bounded along
the chain of levels on one period of the source's top grid, wrapped, and their bounds are the terrain's height
range. The extension may hold any whole number k of periods a side; for k not a power of two its last tiles of a
coarse level cover the padding beyond it, as any grid's do. The extension's samples are the source's, so it keeps
the source's ``source_step``. When the source has the raster strategies' node arrays, the extension serves its
own from them, window by window (``hybrid.tiles.periodic_nodes``: the source's values away from the seams,
conservative bounds near them).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.store_chunks import ChunkRead, chunk_reader, sliced_reader
from hybrid.terrain.stored import LazyGrid, StoredTerrain, open_store

from .periodic_nodes import PeriodicNodes
from .seams import profile_spans, seam_profiles
from .store_prepare import _levels
from .subsampling import block_reduce, interpolate_clamped


class _WrappedLevel:
    """A level's sample grid of the extension: slices of it read the source's level grid, wrapped."""

    def __init__(self, source, period: int, size: int, stride: int = 1):
        self.source, self.period, self.stride = source, period, stride  # period in this level's samples;
        self.shape = (size, size)  # stride: source samples per sample

    def _index(self, s, n: int) -> np.ndarray:
        if isinstance(s, slice):
            return np.arange(*s.indices(n)) % self.period * self.stride
        i = int(s)
        return np.array([(i + n if i < 0 else i) % self.period * self.stride])

    def __getitem__(self, index):
        rows, cols = index
        ri, ci = self._index(rows, self.shape[0]), self._index(cols, self.shape[1])
        r0, r1, c0, c1 = ri.min(), ri.max() + 1, ci.min(), ci.max() + 1
        win = np.asarray(self.source[r0:r1, c0:c1], dtype=np.float32)[np.ix_(ri - r0, ci - c0)]
        if not isinstance(rows, slice):
            win = win[0]
        if not isinstance(cols, slice):
            win = win[..., 0]
        return win

    @property
    def vindex(self):
        return _VIndex(self)

    def chunk_reader(self, n: int) -> ChunkRead:
        """Chunk (cy, cx) of n x n samples, clipped to the grid: the source's chunk (cy, cx) modulo the period, read
        directly, when the period is whole chunks of the source's own level; else a slice of this grid."""
        if self.stride != 1 or self.period % n:
            return sliced_reader(self, (n, n))
        source, t, (rows, cols) = chunk_reader(self.source, (n, n)), self.period // n, self.shape

        def read(cy: int, cx: int) -> np.ndarray:
            r, c = rows - cy * n, cols - cx * n
            if min(cy, cx) < 0 or r <= 0 or c <= 0:
                raise IndexError(f"chunk ({cy}, {cx}) lies outside the wrapped grid of {rows}x{cols}")
            return source(cy % t, cx % t)[:r, :c]

        return read


class _VIndex:
    def __init__(self, level):
        self.level = level

    def __getitem__(self, index):
        i, j = index
        p, k = self.level.period, self.level.stride
        return self.level.source.vindex[np.asarray(i) % p * k, np.asarray(j) % p * k]


class PeriodicStore:
    """The store-like view of an extension: ``attrs`` and the per-level arrays StorePyramid reads."""

    def __init__(self, terrain: StoredTerrain, size: int):
        g = terrain.store
        src_attrs = dict(g.attrs)
        n, P = int(src_attrs["tile_size"]), terrain.cols - 1
        _check_extension(terrain, size, n, P)
        self.source, self.n, self.P, self.size = g, n, P, int(size)
        L = _levels(size, size, n)
        self.attrs = {
            **src_attrs,
            "max_level": L,
            "name": f"{src_attrs['name']}-periodic-{size}",
            "periodic": {"source": terrain.path, "period_cells": P, "size": int(size)},
        }
        seams = seam_profiles(terrain.heights, P)  # the seams' samples (corner included) and steps
        lo, hi = terrain.height_range
        self.arrays: dict[str, Any] = {}
        src_L = int(src_attrs["max_level"])
        beyond: dict = {}
        for level in range(L + 1):
            span = n << level
            tiles = -(-(size - 1) // span)  # the last may cover padding (k not a power of two)
            if span <= P and level <= src_L:
                zmin, zmax, err = _within_period(g, level, tiles, span, P, seams)
            else:  # tiles of whole periods: the periodic chain bound
                if not beyond:  # from the top source level's errors, seams included
                    beyond = _whole_period_errors(g, src_L, L, float(self.arrays[f"error/{src_L}"].max()))
                zmin, zmax = np.full((tiles, tiles), lo), np.full((tiles, tiles), hi)
                err = np.full((tiles, tiles), beyond[level])
            self._add_level(level, zmin, zmax, err, src_L)

        self._add_nodes(src_attrs.get("nodes"), seams, terrain.height_range)

    def _add_level(self, level: int, zmin, zmax, err, src_L: int) -> None:
        """A level's tile bounds and errors (level 0's none, every level's at least its children's) and its samples,
        the source's level grid wrapped (above the source's levels, its top grid strided)."""
        if level == 0:
            err = np.zeros_like(err)  # level 0 is the extension's own samples
        if level:  # monotone, as every pyramid's errors
            err = np.maximum(err, block_reduce(self.arrays[f"error/{level - 1}"], 2, np.maximum))
        self.arrays[f"zmin/{level}"], self.arrays[f"zmax/{level}"] = zmin, zmax
        self.arrays[f"error/{level}"] = err
        src_level = min(level, src_L)  # above the source's levels: its top grid, strided
        self.arrays[f"levels/{level}"] = _WrappedLevel(
            self.source[f"levels/{src_level}"],
            max(self.P >> level, 1),
            ((self.size - 1) >> level) + 1,
            1 << (level - src_level),
        )

    def _add_nodes(self, info, seams, height_range) -> None:
        """The raster strategies' node arrays, served from the source's (hybrid.tiles.periodic_nodes), when the
        source has them; ``attrs["nodes"]`` then describes the extension's."""
        self.attrs.pop("nodes", None)
        if not info or int(info["square"]) != self.P:
            return
        square = self.n << int(self.attrs["max_level"])
        nodes = PeriodicNodes(
            self.source, self.P, (self.size - 1) // self.P, square, seams, float(info["beta"]), height_range
        )
        self.attrs["nodes"] = {**info, "levels": nodes.levels, "square": square, "periodic": True}
        for kind in nodes.kinds:
            for lev in range(nodes.levels):
                self.arrays[f"nodes/{kind}/{lev}"] = nodes.level(kind, lev)

    def __getitem__(self, name):
        return self.arrays[name]


def _check_extension(terrain: StoredTerrain, size, n: int, P: int) -> None:
    """Refuse an extension of a store that is not square with a power-of-two period of at least a tile, or to a
    size that is not a whole number of periods (plus one sample) larger than the store, up to 2^24 + 1."""
    if terrain.rows != terrain.cols:
        raise TerrabenchError(
            f"{terrain.path}: a periodic extension needs a square store, got {terrain.cols}x{terrain.rows} samples"
        )
    if P & (P - 1) or P < n:
        raise TerrabenchError(
            f"{terrain.path}: a periodic extension needs a period of a power of two cells "
            f"of at least one tile ({n}), got {P}"
        )
    if (
        isinstance(size, bool)
        or not isinstance(size, (int, np.integer))
        or size <= terrain.cols
        or (size - 1) % P
        or size > (1 << 24) + 1
    ):
        raise TerrabenchError(
            f"periodic size must be k x {P} + 1 samples, larger than the store and at most "
            f"{(1 << 24) + 1}, got {size!r}"
        )


def _within_period(g, level: int, tiles: int, span: int, P: int, seams) -> tuple:
    """(zmin, zmax, error) of a level whose tiles lie within one period: the source tiles', those on a seam
    widened by the source's first row or column over their span and their error by twice the seam's step."""
    t = P // span
    idx = np.arange(tiles) % t
    seam = idx == t - 1
    zmin = np.asarray(g[f"zmin/{level}"][:])[np.ix_(idx, idx)]
    zmax = np.asarray(g[f"zmax/{level}"][:])[np.ix_(idx, idx)]
    err = np.asarray(g[f"error/{level}"][:])[np.ix_(idx, idx)]
    # per source tile row/column span: the seam's step and the first row/column's range
    step_r = profile_spans(seams.col_step, span, np.maximum)[idx]
    step_c = profile_spans(seams.row_step, span, np.maximum)[idx]
    c_lo, c_hi = (profile_spans(seams.col0, span, fn)[idx] for fn in (np.minimum, np.maximum))
    r_lo, r_hi = (profile_spans(seams.row0, span, fn)[idx] for fn in (np.minimum, np.maximum))
    east, north = seam[None, :], seam[:, None]
    zmin = np.where(east, np.minimum(zmin, c_lo[:, None]), zmin)
    zmin = np.where(north, np.minimum(zmin, r_lo[None, :]), zmin)
    zmax = np.where(east, np.maximum(zmax, c_hi[:, None]), zmax)
    zmax = np.where(north, np.maximum(zmax, r_hi[None, :]), zmax)
    extra = np.where(east, step_r[:, None], 0.0) + np.where(north, step_c[None, :], 0.0)
    return zmin, zmax, err + 2.0 * extra


def _whole_period_errors(g, src_L: int, L: int, base: float) -> dict:
    """Errors (metres) of extension levels src_L+1..L, whose tiles cover whole periods: ``base``, the extension's
    largest error at the source's top level src_L (seam tiles included), plus, level by level, the largest difference
    between the wrapped surfaces of levels l and l-1 at level l-1's samples (the chain bound of
    hybrid.tiles.store), computed on one period of the source's top grid."""
    if L <= src_L:
        return {}
    top = np.asarray(g[f"levels/{src_L}"][:, :], dtype=np.float64)
    period = top[:-1, :-1]  # one period; the wrap supplies the closing row/column
    out, err, grid = {}, base, period
    for level in range(src_L + 1, L + 1):
        if grid.shape[0] < 2 or grid.shape[0] % 2:
            out[level] = err + float(period.max() - period.min())
            continue
        closed = np.pad(grid, ((0, 1), (0, 1)), mode="wrap")
        err += float(np.abs(interpolate_clamped(closed, 2) - closed).max())
        out[level] = err
        grid = grid[::2, ::2]
    return out


def open_periodic(path, size: int) -> StoredTerrain:
    """The periodic extension of the tile store at ``path`` to size x size samples (virtual; labelled periodic)."""
    terrain = open_store(path)
    view = PeriodicStore(terrain, size)
    grid = LazyGrid(view["levels/0"], terrain.height_range, view.attrs["name"])
    return StoredTerrain(
        grid,
        (terrain.spacing_x, terrain.spacing_y),
        terrain.origin,
        view.attrs["name"],
        None,
        source_step=terrain.source_step,
        source=terrain.path,
        notes=list(terrain.notes)
        + [
            f"periodic extension to {size}x{size} samples of {terrain.cols}x{terrain.rows} "
            f"(wrapped every {terrain.cols - 1} cells; virtual, nothing written)"
        ],
        store=view,
        path=f"{terrain.path}@periodic{size}",
    )


def open_any_store(text: str) -> StoredTerrain:
    """A tile store by path, or its periodic extension as 'PATH@periodicSIZE' (e.g. store@periodic262145)."""
    path, sep, rest = str(text).rpartition("@periodic")
    if sep and rest.isdigit():
        return open_periodic(path, int(rest))
    return open_store(text)
