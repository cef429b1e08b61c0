"""Frame-level restriction of tilelet quadtrees across tile borders, and the per-leaf data the GPU draws
(assembled per tile by ``raster.tilelet_sets``).

Tiles of one frame sit at different pyramid levels; a leaf's global level is tile level + local level.
``restrict_frame`` iterates: each tile's leaf-level map (raster.quadtree.leaf_levels) is computed with caps
on its border units derived from the neighbours' border leaves (global level + 1), until no cap changes.
Caps only ever lower levels, so the loop ends. Borders are compared at level-0-cell resolution (global
cells of the finest terrain grid), so tiles of different levels line up.

Inputs are plain: for each tile its key (level, tx, ty), cells per side n, its ErrorPyramid and tolerance
(metres). Tiles are assumed restricted among themselves (edge neighbours differ by at most one level), as
hybrid's tile tree guarantees; otherwise a TerrabenchError says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.errors import TerrabenchError

from .quadtree import ErrorPyramid, leaf_levels
from .tilelet_sets import OPPOSITE, border_units, errors_at, lean_set, tilelet_set


@dataclass(frozen=True)
class TileLod:
    """Plain per-tile input of the frame pass: key (level, tx, ty), error pyramid, tolerance in metres."""

    key: tuple
    pyramid: ErrorPyramid
    tolerance: float


def _edge_profile(levels: np.ndarray, edge: int) -> np.ndarray:
    """Local leaf levels of the border units along one edge (W, E: south to north; S, N: west to east)."""
    return (levels[:, 0], levels[:, -1], levels[0, :], levels[-1, :])[edge]


def _key(k) -> tuple:
    """(level, tx, ty) of a key given as a tuple or an object with .level/.tx/.ty."""
    if hasattr(k, "level"):
        return (int(k.level), int(k.tx), int(k.ty))
    return tuple(int(v) for v in k)


class _Frame:
    """Working state of the frame pass (keys, maps, per-edge global-level profiles at level-0 cells)."""

    def __init__(self, tiles: list[TileLod], use_effective: bool):
        self.tiles: dict = {}
        ns = {t.pyramid.n for t in tiles}
        if len(ns) > 1:
            raise TerrabenchError(f"all tiles of a frame must have the same cells per side, got {sorted(ns)}")
        self.n = ns.pop() if ns else 0
        for t in tiles:
            k = _key(t.key)
            if k in self.tiles:
                raise TerrabenchError(f"tile key {k} given twice")
            self.tiles[k] = t
        self.use_effective = use_effective
        self.levels: dict = {}
        self.caps = {k: np.full((self.n // 2, self.n // 2), t.pyramid.top, np.int16) for k, t in self.tiles.items()}

    def solve(self, key):
        t = self.tiles[key]
        self.levels[key] = leaf_levels(t.pyramid, t.tolerance, self.caps[key], self.use_effective)

    def profile(self, key, edge: int) -> np.ndarray:
        """Global leaf level along a tile edge at level-0-cell resolution."""
        l = key[0]
        return np.repeat(_edge_profile(self.levels[key], edge).astype(np.int32) + l, 2 << l)

    def neighbour_profile(self, key, edge: int, values=None) -> np.ndarray:
        """The neighbours' global levels (or ``values(key, edge)``) along this tile's edge; -1 where none."""
        l, tx, ty = key
        n = self.n
        span = n << l
        x0, y0 = tx * span, ty * span
        out = np.full(span, -1, dtype=np.float64 if values else np.int32)
        if edge in (0, 1):
            x = x0 - 1 if edge == 0 else x0 + span
            a0 = y0
        else:
            x = y0 - 1 if edge == 2 else y0 + span
            a0 = x0
        if x < 0:
            return out
        for lv in (l - 1, l, l + 1):
            if lv < 0:
                continue
            sp = n << lv
            across = x // sp
            for along in range(a0 // sp, (a0 + span - 1) // sp + 1):
                nk = (lv, across, along) if edge in (0, 1) else (lv, along, across)
                if nk not in self.levels:
                    continue
                if abs(lv - l) > 1:
                    continue
                prof = values(nk, OPPOSITE[edge]) if values else self.profile(nk, OPPOSITE[edge])
                s0 = along * sp
                lo, hi = max(s0, a0), min(s0 + sp, a0 + span)
                out[lo - a0 : hi - a0] = prof[lo - s0 : hi - s0]
        return out

    def cap_profile(self, key, edge: int) -> np.ndarray:
        """The finest global level this tile's border leaves allow across an edge, at level-0 cells: one coarser
        than theirs, or theirs where a leaf's side error toward the edge needs its midpoint (above its
        tolerance, by beta where splits follow the effective errors: the side then morphs as the GPU's)."""
        t = self.tiles[key]
        levels = self.levels[key]
        need = np.zeros(levels.shape[0], bool)
        if t.pyramid.sides:
            ua, ub = border_units(levels.shape[0], edge)
            m = levels[ua, ub].astype(np.int64)
            side = errors_at([d[edge] for d in t.pyramid.sides], ua, ub, m)
            need = side > t.tolerance * (t.pyramid.beta if self.use_effective else 1.0)
        return self.profile(key, edge) + 1 - np.repeat(need, 2 << key[0])

    def border_caps(self, key) -> bool:
        """Lower this tile's border caps from its neighbours; True if any cap changed. A neighbour's leaf that
        needs its midpoint toward this tile caps it at the leaf's own level, or this tile's finest where that is
        finer (a tile of the finer pyramid level: its midpoint is then dropped beyond its tolerance)."""
        l = key[0]
        cap = self.caps[key]
        U = cap.shape[0]
        changed = False
        for edge in range(4):
            nb = self.neighbour_profile(key, edge)
            if np.all(nb < 0):
                continue
            big = np.where(nb < 0, 1 << 20, nb).reshape(U, 2 << l).min(axis=1)
            local = np.where(big >= 1 << 20, 1 << 14, big + 1 - l)
            if local.min() < 0:
                raise TerrabenchError(
                    f"tile {key} borders a tile two or more levels finer on edge {'WESN'[edge]}; "
                    "the tiles of a frame must be restricted"
                )
            allow = self.neighbour_profile(key, edge, values=self.cap_profile)
            allow = np.where(allow < 0, 1 << 20, allow).reshape(U, 2 << l).min(axis=1)
            local = np.minimum(local, np.maximum(np.where(allow >= 1 << 20, 1 << 14, allow - l), 0))
            idx = (np.s_[:, 0], np.s_[:, -1], np.s_[0, :], np.s_[-1, :])[edge]
            new = np.minimum(cap[idx], local.astype(np.int16))
            if np.any(new < cap[idx]):
                cap[idx] = new
                changed = True
        return changed


def restrict_frame(
    tiles: list[TileLod],
    morph: bool = True,
    use_effective: bool | None = None,
    lean: bool = False,
    exact_full_resolution: bool = True,
) -> dict:
    """Restricted leaf sets of all tiles of a frame: {key tuple: TileletSet}; morph=False gives zero morph.

    use_effective (default: same as morph) splits on the morph-safe effective errors instead of the plain ones.
    lean drops, as the GPU selection's lean leaves (raster/select.comp.glsl), the edge midpoints between leaves
    of one tile that are both far from their own split (tolerance >= E / beta; with morph=False, >= E: the
    error bounds a leaf's fan with its midpoints dropped; with side errors, the larger of E and the side's
    error on either side), and toward the terrain's edge; midpoints on tile borders and of full-resolution leaves
    are kept (``exact_full_resolution`` False: those leaves drop theirs as others do, and level-0 leaves' SE and NW
    cells turn diagonal as their midpoints morph: the GPU's full_res "lean").
    """
    use_effective = morph if use_effective is None else use_effective
    fr = _Frame(list(tiles), use_effective)
    for k in fr.tiles:
        fr.solve(k)
    pending = set(fr.tiles)
    while pending:
        nxt = set()
        for k in sorted(pending):
            if fr.border_caps(k):
                fr.solve(k)
                nxt.add(k)
                nxt.update(_neighbour_keys(fr, k))
        pending = nxt
    sets = {k: tilelet_set(fr, k, morph) for k in fr.tiles}
    if not lean:
        return sets
    return {k: lean_set(fr, k, ts, morph, exact_full_resolution) for k, ts in sets.items()}


def _neighbour_keys(fr: _Frame, key) -> set:
    l, tx, ty = key
    out = set()
    for k in fr.tiles:
        kl, kx, ky = k
        if abs(kl - l) > 1 or k == key:
            continue
        # overlap test of the two squares' closures in level-0 cells (edge contact only matters)
        s1, s2 = fr.n << l, fr.n << kl
        ax0, ay0, bx0, by0 = tx * s1, ty * s1, kx * s2, ky * s2
        if ax0 <= bx0 + s2 and bx0 <= ax0 + s1 and ay0 <= by0 + s2 and by0 <= ay0 + s1:
            out.add(k)
    return out
