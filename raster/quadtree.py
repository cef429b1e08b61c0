"""Restricted quadtree of tilelets inside one tile: error pyramid, per-view leaf levels, leaf lists.

A tile has n cells a side (n a power of two >= 2). A node at local level m covers 2^(m+1) x 2^(m+1) tile
cells; drawn as a leaf it is a tilelet: 3x3 posts at spacing 2^m cells, an 8-triangle fan around the
centre post (paper §3.2). Levels run 0 (posts = every tile sample) .. top = log2(n) - 1 (one tilelet for
the whole tile). Node (a, b) of level m has its south-west post at tile sample (row a*2^(m+1), col b*2^(m+1)).

Error pyramid (view-independent, computed once per tile):
- ``errors[m]``: the largest vertical distance in metres between a node's full fan and the tile's samples it
  covers, made monotone (a parent's error is at least its children's), and at least the side errors (below) of
  the level-(m-1) nodes outside it that face it (their midpoint toward it needs it split).
- ``sides[m]``: (4, N, N) per node, the largest vertical distance under each triangle of its stitched fan (sides
  W, E, S, N: the edge's midpoint dropped). A leaf keeps an edge's midpoint while the side error on either side
  of the edge is above the tolerance (a leaf's error is bounded by the full fan's where a midpoint stays, by
  the side's where it is dropped, and by the larger of the two while it morphs), so a node whose full fan meets
  the tolerance is a leaf even where dropping a midpoint would not (the half level of a 4-8 mesh: 4 to 8
  triangles a leaf, as the error asks, not 4 or 16).
- ``effective[m]``: ``errors`` raised so that a node's value is at least 1/beta times that of its children and of
  every level-(m-1) node touching its edges from outside, and 1/beta times those outside nodes' side errors
  toward it. Splitting on it ("split while effective > tolerance") gives a quadtree that is restricted inside
  the tile by construction, lets the morph factors of raster.morph reach 0 before any neighbour splits (so no
  vertex ever jumps), and drops a midpoint toward a coarser neighbour only where its side meets the tolerance
  by the factor beta (the midpoint is then on its edge already).
With ``side_errors=False`` the errors are those of the full and the stitched fan together (level 0's with the
cell-centre terms of its sides) and ``sides`` are zero (a leaf may drop any midpoint): the form a periodic
extension's nodes near its seams hold (``hybrid.tiles.periodic_nodes``).

Leaf levels are kept as a map over level-0 tilelets ("units", (n/2) x (n/2)): the level of the leaf
covering each unit. Restriction: edge-adjacent units differ by at most one level; caps (max level per
unit, from neighbouring tiles) force extra splits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.contract import FULL_RES
from hybrid.errors import TerrabenchError
from hybrid.tiles.fans import (  # noqa: F401  (GPU_BETA: the strategies' beta, defined with the fans)
    GPU_BETA,
    cell_centre_error,
    cell_max,
    facing_side_errors,
    fans_at,
    side_maxima,
    with_cell_centres,
)
from hybrid.tiles.fans import dilate4 as _dilate4

DEFAULT_BETA = 0.7


def check_full_res(full_res) -> str:
    """The full-resolution rule, checked against ``hybrid.contract.FULL_RES``."""
    if full_res not in FULL_RES:
        raise TerrabenchError(f"full_res must be one of {', '.join(FULL_RES)}, got {full_res!r}")
    return full_res


def _check_tile_size(n) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2 or n & (n - 1):
        raise TerrabenchError(f"tile cells per side must be a power of two >= 2, got {n!r}")
    return int(n)


def _block(a: np.ndarray, b: int, fn) -> np.ndarray:
    """Reduce a square array over b x b blocks with fn (np.max, np.min, np.any)."""
    if b == 1:
        return a
    m = a.shape[0] // b
    return fn(a.reshape(m, b, m, b), axis=(1, 3))


def _expand(a: np.ndarray, b: int) -> np.ndarray:
    """Repeat every element of a square array into a b x b block."""
    if b == 1:
        return a
    m = a.shape[0]
    return np.broadcast_to(a[:, None, :, None], (m, b, m, b)).reshape(m * b, m * b)


def _erode4(a: np.ndarray, fill) -> np.ndarray:
    """Min over the four edge neighbours of each element (not the element itself); ``fill`` outside."""
    out = np.full_like(a, fill)
    np.minimum(out[1:], a[:-1], out=out[1:])
    np.minimum(out[:-1], a[1:], out=out[:-1])
    np.minimum(out[:, 1:], a[:, :-1], out=out[:, 1:])
    np.minimum(out[:, :-1], a[:, 1:], out=out[:, :-1])
    return out


def fan_surfaces(heights: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Heights (metres, float64) of the level-m tilelet fans at every tile sample: (full fan, stitched fan).

    The full fan splits each of a tilelet's four quadrants along the diagonal through the centre post; the
    stitched fan is the four triangles centre-corner-corner (every edge midpoint dropped); see hybrid.tiles.fans.
    """
    h = np.asarray(heights, dtype=np.float64)
    n = _check_tile_size(h.shape[0] - 1)
    if (2 << m) > n:
        raise TerrabenchError(f"tilelet level m must lie in [0, {int(np.log2(n)) - 1}] for a {n}-cell tile, got {m}")
    idx = np.arange(n + 1)
    return fans_at(h, 0, 0, idx, idx, m, n)


@dataclass(frozen=True)
class ErrorPyramid:
    """Per-node vertical errors (metres vs the tile's samples) of one tile, levels 0..top.

    errors[m] and effective[m] have shape (n >> (m+1))² with row a from the south, column b from the west;
    sides[m] (4, ...) the same per stitched-fan side W, E, S, N (empty: none measured, as zeros).
    zmin/zmax[m]: range of the tile's sample heights under each node (metres, relative to terrain origin z).
    """

    n: int
    beta: float
    errors: tuple
    effective: tuple
    zmin: tuple
    zmax: tuple
    sides: tuple = ()

    @property
    def top(self) -> int:
        """The coarsest local level (one tilelet for the whole tile)."""
        return len(self.errors) - 1

    @property
    def units(self) -> int:
        """Level-0 tilelets per side (n / 2)."""
        return self.n // 2


def error_pyramid(heights: np.ndarray, beta: float = DEFAULT_BETA, side_errors: bool = True) -> ErrorPyramid:
    """Error pyramid (metres) of a tile's (n+1)² heights; beta in (0, 1) sets the morph-safe error growth;
    side_errors: split on the full fan's errors with per-side stitched errors (False: both fans in one error)."""
    h = np.asarray(heights)
    if h.ndim != 2 or h.shape[0] != h.shape[1]:
        raise TerrabenchError(f"tile heights must be a square (n+1)x(n+1) array, got shape {h.shape}")
    n = _check_tile_size(h.shape[0] - 1)
    if not (0.0 < float(beta) < 1.0):
        raise TerrabenchError(f"beta must lie in (0, 1), got {beta!r}")
    h = h.astype(np.float64)
    top = int(np.log2(n)) - 1
    cmax = np.maximum(np.maximum(h[:-1, :-1], h[:-1, 1:]), np.maximum(h[1:, :-1], h[1:, 1:]))
    cmin = np.minimum(np.minimum(h[:-1, :-1], h[:-1, 1:]), np.minimum(h[1:, :-1], h[1:, 1:]))
    errors: list[np.ndarray]
    effective: list[np.ndarray]
    errors, effective, sides, zmin, zmax = [], [], [], [], []
    for m in range(top + 1):
        full, stitched = fan_surfaces(h, m)
        b = 2 << m
        if side_errors:
            e = _block(cell_max(np.abs(full - h)), b, np.max)
            sides.append(side_maxima(np.abs(stitched - h), m))
            if m == 0:
                sides[0] = with_cell_centres(h, sides[0])
        else:
            e = _block(cell_max(np.maximum(np.abs(full - h), np.abs(stitched - h))), b, np.max)
            if m == 0:  # a drop's turn of the SE and NW cells' diagonals
                e = np.maximum(e, cell_centre_error(h))
            sides.append(np.zeros((4,) + e.shape))  # toward coarser neighbours: within e already
        del full, stitched
        zmin.append(_block(cmin, b, np.min))
        zmax.append(_block(cmax, b, np.max))
        if m > 0:
            facing = _block(facing_side_errors(sides[-2]), 2, np.max)
            e = np.maximum(np.maximum(e, _block(errors[-1], 2, np.max)), facing)
            eff = np.maximum(e, np.maximum(_block(_dilate4(effective[-1]), 2, np.max), facing) / beta)
        else:
            eff = e
        errors.append(e)
        effective.append(eff)
    return ErrorPyramid(
        n, float(beta), tuple(errors), tuple(effective), tuple(zmin), tuple(zmax), tuple(sides) if side_errors else ()
    )


def leaf_levels(
    pyr: ErrorPyramid, tolerance: float, cap: np.ndarray | None = None, use_effective: bool = True
) -> np.ndarray:
    """Map (n/2)² of leaf local levels: split while error > tolerance (metres), restricted, level <= cap."""
    tol = float(tolerance)
    if not (tol >= 0.0) or tol == np.inf:
        raise TerrabenchError(f"tolerance must be finite and >= 0 metres, got {tolerance!r}")
    E = pyr.effective if use_effective else pyr.errors
    top, U = pyr.top, pyr.units
    if cap is None:
        cap = np.full((U, U), top, dtype=np.int16)
    else:
        cap = np.asarray(cap, dtype=np.int16)
        if cap.shape != (U, U):
            raise TerrabenchError(f"cap must have shape {(U, U)}, got {cap.shape}")
        if cap.min() < 0:
            raise TerrabenchError(f"cap levels must be >= 0, got minimum {int(cap.min())} (tiles not restricted?)")
    need = [e > tol for e in E]
    while True:
        levels = np.full((U, U), top, dtype=np.int16)
        below = None
        for m in range(1, top + 1):
            s = need[m] | (_block(cap, 1 << m, np.min) < m)
            if below is not None:
                s |= _block(below, 2, np.any)
            below = s
            levels -= _expand(s, 1 << m).astype(np.int16)
        allowed = _erode4(levels, top) + 1
        if not np.any(levels > allowed):
            return levels
        cap = np.minimum(cap, allowed)


@dataclass(frozen=True)
class Leaves:
    """Leaves of one tile: south-west post (row i0, column j0 in tile cells) and local level, int32 arrays."""

    i0: np.ndarray
    j0: np.ndarray
    level: np.ndarray

    def __len__(self) -> int:
        return int(self.level.size)

    @property
    def size(self) -> np.ndarray:
        """Side of each leaf in tile cells (2^(level+1))."""
        return 2 << self.level


def leaves_from_levels(levels: np.ndarray) -> Leaves:
    """The leaf list of a leaf-level map (one entry per leaf, coarsest levels first)."""
    U = levels.shape[0]
    top = int(np.log2(U)) if U > 1 else 0
    i0s, j0s, ms = [], [], []
    for m in range(top, -1, -1):
        step = 1 << m
        a, b = np.nonzero(levels[::step, ::step] == m)
        i0s.append(a * 2 * step)
        j0s.append(b * 2 * step)
        ms.append(np.full(a.size, m))
    cat = lambda xs: np.concatenate(xs).astype(np.int32)  # noqa: E731
    return Leaves(cat(i0s), cat(j0s), cat(ms))


def leaf_heights(heights: np.ndarray, leaves: Leaves) -> np.ndarray:
    """(count, 3, 3) post heights of each leaf (metres), [row from south, column from west]."""
    h = np.asarray(heights)
    k = 1 << leaves.level
    r = leaves.i0[:, None] + k[:, None] * np.arange(3)[None, :]
    c = leaves.j0[:, None] + k[:, None] * np.arange(3)[None, :]
    return h[r[:, :, None], c[:, None, :]]


def drawn_max_error(heights: np.ndarray, leaves: Leaves, dropped: np.ndarray | None = None) -> np.ndarray:
    """Per leaf: max vertical distance (metres) between its drawn (stitched, unmorphed) fan and the tile samples.

    dropped: per leaf bit mask of edges W=1, E=2, S=4, N=8 whose midpoint is dropped (None: none).
    """
    h = np.asarray(heights, dtype=np.float64)
    out = np.zeros(len(leaves))
    dropped = np.zeros(len(leaves), np.int32) if dropped is None else np.asarray(dropped)
    for m in np.unique(leaves.level):
        sel = np.nonzero(leaves.level == m)[0]
        k = 1 << int(m)
        t = np.arange(2 * k + 1)
        r = leaves.i0[sel, None] + t[None, :]
        c = leaves.j0[sel, None] + t[None, :]
        samples = h[r[:, :, None], c[:, None, :]]
        P = samples[:, ::k, ::k]
        tt = t / k
        surf = fan_at(P, tt[None, :], tt[:, None], dropped[sel])
        out[sel] = np.abs(surf - samples).max(axis=(1, 2))
    return out


def fan_at(P: np.ndarray, u: np.ndarray, v: np.ndarray, dropped) -> np.ndarray:
    """Heights of fans with posts P (..., 3, 3) [row, col] at local (u east, v north) in [0, 2] (post units).

    dropped (...,): edge bits W=1, E=2, S=4, N=8 whose midpoint is left out (stitched). Result (..., *uv).
    """
    P = np.asarray(P, dtype=np.float64)
    lead = P.shape[:-2]
    ex = (slice(None),) * len(lead) + (None, None)
    dropped = np.broadcast_to(np.asarray(dropped), lead)[ex]
    c = P[..., 1, 1][ex]
    below_main = v <= u
    below_anti = v <= 2.0 - u
    sector = np.where(below_main, np.where(below_anti, 0, 1), np.where(below_anti, 3, 2))  # S, E, N, W
    out = np.zeros(lead + np.broadcast(u, v).shape)
    # per sector: the edge's corners a, b and midpoint, coordinate s along it, distance w from the centre
    # line (1 on the edge, 0 at the centre); the fan is linear along rays from the centre
    sectors = (
        (0, (0, 0), (0, 1), (0, 2), u, 1.0 - v, 4),
        (1, (0, 2), (1, 2), (2, 2), v, u - 1.0, 2),
        (2, (2, 0), (2, 1), (2, 2), u, v - 1.0, 8),
        (3, (0, 0), (1, 0), (2, 0), v, 1.0 - u, 1),
    )
    for sec, ia, im, ib, s, w, bit in sectors:
        a, mid, b = P[..., ia[0], ia[1]][ex], P[..., im[0], im[1]][ex], P[..., ib[0], ib[1]][ex]
        with np.errstate(divide="ignore", invalid="ignore"):
            foot = np.where(w > 0, 1.0 + (s - 1.0) / np.where(w > 0, w, 1.0), 1.0)
        split = np.where(foot <= 1.0, a + foot * (mid - a), mid + (foot - 1.0) * (b - mid))
        straight = a + 0.5 * foot * (b - a)
        edge = np.where((dropped & bit) != 0, straight, split)
        out = np.where(sector == sec, c + w * (edge - c), out)
    return out
