"""Per-view tile selection: frustum culling, screen-space error refinement, restriction, front-to-back order.

A tile is refined while its projected geometric error exceeds tau pixels (default 2/3, Dick et al. §4):
``error_m * K / d`` (error_m: the geometric error plus the bound on the 16-bit quantisation error of the ray
caster's heights, hybrid.tiles.quantize, so the bound holds whichever strategy draws the tile) with K = viewport height / (2 tan(fov/2)) and d the distance from the eye to the
nearest point of the tile's AABB. Selected tiles are then made restricted (edge neighbours differ by at
most one level) by splitting coarse tiles, and listed front to back by a quadtree traversal that visits
the child quadrant on the eye's side first and the opposite one last, which is a visibility order for
height-field columns. A pyramid of a few thousand tile places is selected over all of them at once
(hybrid.tiles.tile_table), with the same result.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from hybrid.camera.view import View
from hybrid.errors import check_positive
from hybrid.tiles.pyramid import EDGE_E, EDGE_N, EDGE_S, EDGE_W, TileKey, TilePyramid
from hybrid.tiles.tile_table import DENSE_MAX_TILES, dense_selection, square_tiles

DEFAULT_TAU = 2.0 / 3.0
NO_NEIGHBOUR = 9
_EDGES = ((EDGE_W, -1, 0), (EDGE_E, 1, 0), (EDGE_S, 0, -1), (EDGE_N, 0, 1))
_STEPS = np.array([(dx, dy) for _, dx, dy in _EDGES])  # (4, 2) tile steps to the W, E, S, N neighbours
_EDGE_BITS = np.array([bit for bit, _, _ in _EDGES])


class SelectedTile(NamedTuple):
    """A tile chosen for a view, with what the renderers and the cost model need to know about it (a named tuple:
    one is made for every selected tile of every frame).

    distance: metres from the eye to the nearest point of the AABB (0 if the eye is inside it).
    projected_error: the tile's geometric error in pixels at that distance.
    coarser_edges: bit mask of edges (EDGE_W/E/S/N) whose neighbour is one level coarser (stitch there).
    inside: True if the AABB lies wholly inside the frustum (no finer culling needed).
    edge_deltas: per edge W, E, S, N, the level of the selected tile across it minus this tile's level
      (-1, 0 or 1; NO_NEIGHBOUR where no selected tile touches that edge).
    """

    key: TileKey
    distance: float
    projected_error: float
    coarser_edges: int
    inside: bool
    edge_deltas: tuple = (9, 9, 9, 9)

    @property
    def level(self) -> int:
        """Pyramid level of the tile."""
        return self.key.level


def covering_tile(selected, key: TileKey, max_level: int) -> TileKey | None:
    """The selected tile at key's level or coarser that contains key's area, or None."""
    l, x, y = key.level, key.tx, key.ty
    while l <= max_level:
        k = TileKey(l, x, y)
        if k in selected:
            return k
        l, x, y = l + 1, x // 2, y // 2
    return None


def box_distances(eye: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Euclidean distances (metres) from a point to (B, 3) axis-aligned boxes; 0 inside.

    Summed x, y, z in that order (not ``np.linalg.norm``, whose summation differs between a vector and an
    axis), so a box gets the same bits here as from the scalar formula."""
    d = np.maximum(np.maximum(lo - eye, eye - hi), 0.0)
    return np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])


_SHIFT = 29  # tile codes: level << 58 | ty << 29 | tx (tiles a side < 2^29)


def _codes(level, tx, ty) -> np.ndarray:
    """int64 codes of tiles given as (broadcastable) arrays of level, tx, ty."""
    return (
        (np.asarray(level, np.int64) << (2 * _SHIFT)) | (np.asarray(ty, np.int64) << _SHIFT) | np.asarray(tx, np.int64)
    )


def _member(sorted_codes: np.ndarray, cand: np.ndarray) -> np.ndarray:
    """Boolean array of cand's shape: which candidate codes are in the sorted code array."""
    if not len(sorted_codes):
        return np.zeros(cand.shape, bool)
    pos = np.minimum(np.searchsorted(sorted_codes, cand), len(sorted_codes) - 1)
    return sorted_codes[pos] == cand


def corner_planes(planes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M (6, 12), offsets (12,)) with which ``box_classes`` is one product: for eye-relative boxes X = [lo | hi]
    (B, 6), X @ M + offsets holds each plane's value at the box corner farthest along its normal (6 columns), then
    at the nearest (6). Made once a view."""
    n, off = planes[:, :3].T, planes[:, 3]
    npos, nneg = np.maximum(n, 0.0), np.minimum(n, 0.0)
    m = np.empty((6, 12))
    m[:3, :6], m[:3, 6:], m[3:, :6], m[3:, 6:] = nneg, npos, npos, nneg
    return m, np.concatenate([off, off])


def box_classes(x: np.ndarray, m: np.ndarray, off: np.ndarray) -> np.ndarray:
    """Frustum classes of eye-relative boxes x = [lo | hi] (B, 6) under ``corner_planes``' (m, off): (B,) int8 of
    -1 outside, 1 wholly inside, 0 crossing a plane."""
    v = x @ m + off
    out = (v[:, 6:] >= 0).all(axis=1).astype(np.int8)  # the nearest corner inside every plane
    out[(v[:, :6] < 0).any(axis=1)] = -1  # the farthest corner outside one
    return out


class _Selection:
    """The selected tiles of one view as parallel arrays, with what each needs (distance, projected error, class)."""

    def __init__(self, pyramid: TilePyramid, view: View, tau: float):
        self.pyramid, self.eye, self.tau = pyramid, np.asarray(view.eye, dtype=np.float64), tau
        self.planes, self.K = view.frustum_planes_rel(), view.pixels_per_radian
        self.corners = corner_planes(self.planes)
        self.eye2 = np.concatenate([self.eye, self.eye])
        self.parts: list[tuple[np.ndarray, ...]] = []  # (level, tx, ty, d, pe, c, lo, hi) arrays of selected tiles

    def measure(self, level: int, tx: np.ndarray, ty: np.ndarray):
        """Existing, not culled tiles of a level among (tx, ty), with distance, projected error and class."""
        ok = self.pyramid.exists_at(level, tx, ty)
        if not ok.all():
            tx, ty = tx[ok], ty[ok]
        t = self.pyramid.level_table(level)[ty, tx]  # lo, hi, error: (B, 7)
        c = box_classes(t[:, :6] - self.eye2, *self.corners)
        keep = c >= 0
        if not keep.all():
            tx, ty, t, c = tx[keep], ty[keep], t[keep], c[keep]
        d, pe = self.distances_errors(t)
        return tx, ty, d, pe, c, t[:, :3], t[:, 3:6]

    def distances_errors(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(distance (B,) metres, projected error (B,) pixels) of rows [lo | hi | error] of ``level_table``."""
        d = box_distances(self.eye, t[:, :3], t[:, 3:6])
        err = t[:, 6]
        with np.errstate(divide="ignore", invalid="ignore"):
            pe = np.where(d > 0, err * self.K / d, np.where(err > 0, np.inf, 0.0))
        return d, pe

    def measure_all(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(distance, projected error, class) of every row [lo | hi | error] (``dense_selection``'s measure)."""
        return (*self.distances_errors(t), box_classes(t[:, :6] - self.eye2, *self.corners))

    def refine(self) -> None:
        """Split from the root down, one level at a time, while the projected error exceeds tau."""
        level = self.pyramid.max_level
        tx, ty = np.zeros(1, np.int64), np.zeros(1, np.int64)
        while level >= 0 and len(tx):
            tx, ty, d, pe, c, lo, hi = self.measure(level, tx, ty)
            split = (pe > self.tau) & (level > 0)
            keep = ~split
            self.parts.append(
                (np.full(int(keep.sum()), level), tx[keep], ty[keep], d[keep], pe[keep], c[keep], lo[keep], hi[keep])
            )
            tx, ty = _children(tx[split], ty[split])
            level -= 1

    def arrays(self):
        """(level, tx, ty, d, pe, c, lo, hi) of every selected tile, concatenated (lo, hi: (N, 3) box corners)."""
        if not self.parts:
            return (*(np.zeros(0) for _ in range(6)), np.zeros((0, 3)), np.zeros((0, 3)))
        return tuple(np.concatenate([part[i] for part in self.parts]) for i in range(8))

    def edge_levels(self, lv, tx, ty) -> np.ndarray:
        """(4, N) per edge W, E, S, N: level of the selected tile at the tile's level or coarser that covers
        the edge neighbour's place, -1 where none (off the pyramid, culled, or finer tiles there)."""
        top = self.pyramid.max_level
        codes = np.sort(_codes(lv, tx, ty))
        t = (1 << (top - lv))[None, None, :]  # tiles a side at each tile's level
        k = np.arange(top + 1)[None, :, None]  # ancestor steps
        nx, ny = tx[None, None, :] + _STEPS[:, 0, None, None], ty[None, None, :] + _STEPS[:, 1, None, None]
        ok = (nx >= 0) & (nx < t) & (ny >= 0) & (ny < t) & (lv[None, None, :] + k <= top)
        found = ok & _member(codes, _codes(lv[None, None, :] + k, np.maximum(nx, 0) >> k, np.maximum(ny, 0) >> k))
        first = np.argmax(found, axis=1)  # the finest covering level
        return np.where(found.any(axis=1), lv[None, :] + first, -1)

    def finer_neighbours(self, lv, tx, ty) -> np.ndarray:
        """(4, N) per edge: True where a selected tile one level finer lies in the edge neighbour's place."""
        codes = np.sort(_codes(lv, tx, ty))
        nx, ny = tx[None, :] + _STEPS[:, 0, None], ty[None, :] + _STEPS[:, 1, None]
        hit = np.zeros((4, len(lv)), bool)
        for ox, oy in ((0, 0), (1, 0), (0, 1), (1, 1)):
            cand = _codes(np.maximum(lv - 1, 0)[None, :], 2 * np.maximum(nx, 0) + ox, 2 * np.maximum(ny, 0) + oy)
            hit |= _member(codes, cand)
        return hit & (nx >= 0) & (ny >= 0) & (lv > 0)[None, :]

    def restrict(self) -> np.ndarray:
        """Split every selected tile with an edge neighbour two or more levels finer, until none is left;
        returns the final tiles' edge_levels."""
        while True:
            lv, tx, ty = (a.astype(np.int64) for a in self.arrays()[:3])
            cov = self.edge_levels(lv, tx, ty)
            far = cov >= lv[None, :] + 2
            if not far.any():
                return cov
            e, i = np.nonzero(far)
            k = cov[e, i] - lv[i]
            split = np.unique(_codes(cov[e, i], (tx[i] + _STEPS[e, 0]) >> k, (ty[i] + _STEPS[e, 1]) >> k))
            keep = ~np.isin(_codes(lv, tx, ty), split)
            self.parts = [tuple(a[keep] for a in self.arrays())]
            mask = (1 << _SHIFT) - 1
            for level in np.unique(split >> (2 * _SHIFT)):
                at = split[(split >> (2 * _SHIFT)) == level]
                cx, cy = _children(at & mask, (at >> _SHIFT) & mask)
                cx, cy, dist, pe, c, lo, hi = self.measure(int(level) - 1, cx, cy)
                self.parts.append((np.full(len(cx), int(level) - 1), cx, cy, dist, pe, c, lo, hi))

    def front_to_back(self, lv, tx, ty) -> np.ndarray:
        """Order of the tiles by the quadtree traversal that visits the eye's child quadrant first."""
        p, hf = self.pyramid, self.pyramid.hf
        key = np.zeros(len(lv), np.int64)
        for a in range(p.max_level, 0, -1):  # ancestor level a: one base-4 digit each
            below = lv < a
            up = np.maximum(a - lv, 1)  # levels up to the ancestor (masked where not below)
            ax, ay = tx >> up, ty >> up
            qx, qy = (tx >> (up - 1)) & 1, (ty >> (up - 1)) & 1
            span_x, span_y = (p.n << a) * hf.spacing_x, (p.n << a) * hf.spacing_y
            sx = (self.eye[0] >= hf.origin[0] + (ax + 0.5) * span_x).astype(np.int64)
            sy = (self.eye[1] >= hf.origin[1] + (ay + 0.5) * span_y).astype(np.int64)
            rank = (qx != sx).astype(np.int64) + 2 * (qy != sy)
            key |= np.where(below, rank << (2 * (a - 1)), 0)
        return np.argsort(key, kind="stable")


def _children(tx: np.ndarray, ty: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The four children (SW, SE, NW, NE) of each tile (tx, ty), as flat arrays of the next finer level."""
    tx, ty = np.asarray(tx, np.int64), np.asarray(ty, np.int64)
    return (
        np.concatenate([2 * tx, 2 * tx + 1, 2 * tx, 2 * tx + 1]),
        np.concatenate([2 * ty, 2 * ty, 2 * ty + 1, 2 * ty + 1]),
    )


class TileSelection(list[SelectedTile]):
    """Selected tiles front to back (``SelectedTile``s), with the same tiles as arrays in the same order: keys
    (B, 3) int64 level, tx, ty; distance (B,) metres; lo, hi (B, 3) world box corners (metres); inside (B,) bool."""

    __slots__ = ("distance", "hi", "inside", "keys", "lo")
    distance: np.ndarray
    hi: np.ndarray
    inside: np.ndarray
    keys: np.ndarray
    lo: np.ndarray


def select_tiles(
    pyramid: TilePyramid, view: View, tau: float = DEFAULT_TAU, dense: bool | None = None
) -> list[SelectedTile]:
    """Tiles to draw for a view with screen-space error <= tau pixels: restricted, culled, front to back.

    A small pyramid (``hybrid.tiles.tile_table.DENSE_MAX_TILES`` tile places or fewer; ``dense`` forces either
    way) is selected over all its tiles at once (``dense_selection``); a larger one level by level, vectorised
    over each level's tiles, restriction and edge levels by looking up ancestors' codes. Both end in the
    front-to-back order as one sort key per tile.
    """
    tau = check_positive("tau (pixels)", tau)
    sel = _Selection(pyramid, view, tau)
    if dense is None:
        dense = square_tiles(pyramid) <= DENSE_MAX_TILES
    if dense:
        (keys, d, pe, c, lo, hi), cov, finer = dense_selection(pyramid, sel.measure_all, tau, sel.eye)
    else:
        sel.refine()
        cov = sel.restrict()
        lv, tx, ty, d, pe, c, lo, hi = sel.arrays()
        lv, tx, ty = lv.astype(np.int64), tx.astype(np.int64), ty.astype(np.int64)
        finer = sel.finer_neighbours(lv, tx, ty)
        order = sel.front_to_back(lv, tx, ty)
        keys = np.stack([lv, tx, ty], axis=1)[order]
        d, pe, c, lo, hi = d[order], pe[order], c[order], lo[order], hi[order]
        cov, finer = cov[:, order], finer[:, order]
    deltas = np.where(cov >= 0, cov - keys[:, 0][None, :], np.where(finer, -1, NO_NEIGHBOUR)).T
    masks = ((deltas == 1) * _EDGE_BITS).sum(axis=1)
    inside = c == 1
    out = TileSelection(
        SelectedTile(TileKey(level, x, y), dist, err, mask, ins, tuple(delta))
        for (level, x, y), dist, err, mask, ins, delta in zip(
            keys.tolist(), d.tolist(), pe.tolist(), masks.tolist(), inside.tolist(), deltas.tolist()
        )
    )
    out.inside, out.keys = inside, keys
    out.distance, out.lo, out.hi = d.astype(np.float64, copy=False), lo, hi
    return out


def edge_neighbours(keys: set, key: TileKey, dx: int, dy: int, max_level: int) -> list[TileKey]:
    """Tiles of a selection that touch ``key``'s edge in direction (dx, dy): same level, coarser or finer."""
    nx, ny = key.tx + dx, key.ty + dy
    if nx < 0 or ny < 0:
        return []
    cov = covering_tile(keys, TileKey(key.level, nx, ny), max_level)
    if cov is not None:
        return [cov]
    out: list[TileKey] = []
    frontier = [TileKey(key.level, nx, ny)]
    while frontier and frontier[0].level > 0:
        nxt: list[TileKey] = []
        for k in frontier:
            for c in k.children():
                # keep the children on the side that faces key
                if (
                    (dx == 1 and c.tx % 2 == 0)
                    or (dx == -1 and c.tx % 2 == 1)
                    or (dy == 1 and c.ty % 2 == 0)
                    or (dy == -1 and c.ty % 2 == 1)
                ):
                    (out if c in keys else nxt).append(c)
        frontier = nxt
    return out
