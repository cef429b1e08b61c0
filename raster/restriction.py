"""Frame-level restriction of tilelet quadtrees across tile borders, and the per-leaf data the GPU draws.

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

from dataclasses import dataclass, replace

import numpy as np

from hybrid.errors import TerrabenchError

from .morph import morph_factor, turn_factor
from .quadtree import ErrorPyramid, Leaves, leaf_levels, leaves_from_levels

EDGE_W, EDGE_E, EDGE_S, EDGE_N = 1, 2, 4, 8
EDGE_BITS = (EDGE_W, EDGE_E, EDGE_S, EDGE_N)
_OPPOSITE = (1, 0, 3, 2)


@dataclass(frozen=True)
class TileLod:
    """Plain per-tile input of the frame pass: key (level, tx, ty), error pyramid, tolerance in metres."""

    key: tuple
    pyramid: ErrorPyramid
    tolerance: float


@dataclass(frozen=True)
class TileletSet:
    """What one tile draws: leaves, edges whose neighbour is coarser (dropped midpoints) or finer, morph.

    coarser, finer: per leaf bit masks W=1, E=2, S=4, N=8. morph: (count, 5) float32 morph factors in
    [0, 1] of the edge midpoints W, E, S, N and of the centre (0 = own height, 1 = on the coarser surface).
    level_map: (n/2)² local leaf levels. global_level: tile level + leaf level per leaf. dropped: the edges
    drawn without their midpoint, where lean leaves drop more than ``coarser`` (None: just those). turns: (count, 2)
    the SE and NW cells' turns of level-0 leaves whose full-resolution midpoints are lean (select.comp.glsl
    LEAN_FULL_RES; None: no cell turns), each cell drawn as 4 triangles while its turn is above 0.
    """

    leaves: Leaves
    coarser: np.ndarray
    finer: np.ndarray
    morph: np.ndarray
    level_map: np.ndarray
    tile_level: int
    dropped: np.ndarray | None = None
    turns: np.ndarray | None = None

    @property
    def drop(self) -> np.ndarray:
        """Per leaf bit mask (W=1, E=2, S=4, N=8) of the edges drawn without their midpoint."""
        return self.coarser if self.dropped is None else self.dropped

    @property
    def global_level(self) -> np.ndarray:
        """Global level (tile level + local level) of every leaf."""
        return self.leaves.level + self.tile_level

    @property
    def triangles(self) -> int:
        """Triangles drawn with stitching: 8 a leaf, one fewer per dropped edge midpoint, two more per turning cell."""
        turning = 0 if self.turns is None else 2 * int(np.count_nonzero(self.turns > 0))
        return int(8 * len(self.leaves) - np.unpackbits(self.drop.astype(np.uint8)[:, None], axis=1).sum()) + turning


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
                prof = values(nk, _OPPOSITE[edge]) if values else self.profile(nk, _OPPOSITE[edge])
                s0 = along * sp
                lo, hi = max(s0, a0), min(s0 + sp, a0 + span)
                out[lo - a0:hi - a0] = prof[lo - s0:hi - s0]
        return out

    def cap_profile(self, key, edge: int) -> np.ndarray:
        """The finest global level this tile's border leaves allow across an edge, at level-0 cells: one coarser
        than theirs, or theirs where a leaf's side error toward the edge needs its midpoint (above its
        tolerance, by beta where splits follow the effective errors: the side then morphs as the GPU's)."""
        t = self.tiles[key]
        levels = self.levels[key]
        need = np.zeros(levels.shape[0], bool)
        if t.pyramid.sides:
            ua, ub = _border_units(levels.shape[0], edge)
            m = levels[ua, ub].astype(np.int64)
            side = _errors_at([d[edge] for d in t.pyramid.sides], ua, ub, m)
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
                raise TerrabenchError(f"tile {key} borders a tile two or more levels finer on edge {'WESN'[edge]}; "
                                 "the tiles of a frame must be restricted")
            allow = self.neighbour_profile(key, edge, values=self.cap_profile)
            allow = np.where(allow < 0, 1 << 20, allow).reshape(U, 2 << l).min(axis=1)
            local = np.minimum(local, np.maximum(np.where(allow >= 1 << 20, 1 << 14, allow - l), 0))
            idx = (np.s_[:, 0], np.s_[:, -1], np.s_[0, :], np.s_[-1, :])[edge]
            new = np.minimum(cap[idx], local.astype(np.int16))
            if np.any(new < cap[idx]):
                cap[idx] = new
                changed = True
        return changed


def restrict_frame(tiles: list[TileLod], morph: bool = True, use_effective: bool | None = None,
                   lean: bool = False, exact_full_resolution: bool = True) -> dict:
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
    sets = {k: _tilelet_set(fr, k, morph) for k in fr.tiles}
    if not lean:
        return sets
    return {k: _lean_set(fr, k, ts, morph, exact_full_resolution) for k, ts in sets.items()}


def _lean_set(fr: _Frame, key, ts: TileletSet, morph: bool, exact_full_resolution: bool = True) -> TileletSet:
    """The set with its lean drops (``restrict_frame``): midpoints of edges whose leaves' lean factors are 1."""
    t = fr.tiles[key]
    E = t.pyramid.effective if fr.use_effective else t.pyramid.errors
    beta = t.pyramid.beta
    lv, U = ts.leaves, ts.level_map.shape[0]
    m = lv.level.astype(np.int64)
    ua, ub = lv.i0 // 2, lv.j0 // 2

    def factor(a, b, level, side):
        e = _errors_at(E, a, b, level)
        if t.pyramid.sides:                             # the side's own stitched error, where larger
            e = np.maximum(e, _errors_at([d[side] for d in t.pyramid.sides], a, b, level))
        with np.errstate(divide="ignore"):
            r = np.where(e > 0, t.tolerance / np.where(e > 0, e, 1.0), np.inf)
        if not morph:                                   # level-0 leaves may exceed the tolerance: kept
            f = (r >= 1.0).astype(np.float64)
        else:
            f = np.clip((r - 1.0) / (1.0 / beta - 1.0), 0.0, 1.0)
        if not exact_full_resolution:
            return f
        return np.where((level == 0) & (key[0] == 0), 0.0, f)     # full resolution keeps the reference's cells
    dropped = ts.coarser.copy()
    am = np.zeros((len(lv), 4))
    for edge, (inside, na, nb_, along) in enumerate(_edge_neighbours(lv, U)):
        bit = EDGE_BITS[edge]
        own = factor(ua, ub, m, edge)
        na_c, nb_c = np.clip(na, 0, U - 1), np.clip(nb_, 0, U - 1)
        same = inside & (ts.level_map[na_c, nb_c] == m)
        le = np.zeros(len(lv))
        le[same] = np.minimum(own[same], factor(na_c[same], nb_c[same], m[same], _OPPOSITE[edge]))
        edge_of_terrain = ~inside & ((ts.finer & bit) == 0) & \
            (fr.neighbour_profile(key, edge)[along.astype(np.int64) << key[0]] < 0)
        le[edge_of_terrain] = own[edge_of_terrain]
        am[:, edge] = np.maximum(ts.morph[:, edge], le)
        dropped[np.maximum(ts.morph[:, edge], le) >= 1.0] |= bit
    if exact_full_resolution:
        return replace(ts, dropped=dropped)
    level0 = m == 0                                     # edges W, E, S, N: the SE cell's are E and S, the NW's W and N
    turns = np.column_stack([np.where(level0 & (dropped & 6 == 0), turn_factor(np.maximum(am[:, 1], am[:, 2])), 0.0),
                             np.where(level0 & (dropped & 9 == 0), turn_factor(np.maximum(am[:, 0], am[:, 3])), 0.0)])
    return replace(ts, dropped=dropped, turns=turns)


def _errors_at(E, a: np.ndarray, b: np.ndarray, level: np.ndarray) -> np.ndarray:
    """Errors (metres) E[level][a >> level, b >> level] of the nodes of ``level`` covering units (a, b)."""
    out = np.zeros(len(level))
    for x in np.unique(level):
        s = level == x
        out[s] = E[x][a[s] >> x, b[s] >> x]
    return out


def _edge_neighbours(lv: Leaves, U: int) -> tuple:
    """Per edge W, E, S, N of every leaf: (neighbour inside the tile, unit row and column just outside the edge,
    the leaf's border cell index along the edge, for neighbours across the tile border)."""
    ua, ub, su = lv.i0 // 2, lv.j0 // 2, 1 << lv.level.astype(np.int64)
    return ((ub > 0, ua, ub - 1, lv.i0), (ub + su < U, ua, ub + su, lv.i0),
            (ua > 0, ua - 1, ub, lv.j0), (ua + su < U, ua + su, ub, lv.j0))


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


def _own_alpha(fr: _Frame, key, levels: np.ndarray, ua: np.ndarray, ub: np.ndarray) -> np.ndarray:
    """Morph factor of edge midpoints from the leaf's own parent only, for units (ua, ub) (arrays)."""
    t = fr.tiles[key]
    E = t.pyramid.effective if fr.use_effective else t.pyramid.errors
    m = levels[ua, ub].astype(np.int64)
    out = np.zeros(ua.shape, dtype=np.float64)
    s = m < t.pyramid.top
    out[s] = morph_factor(t.tolerance, _errors_at(E, ua[s], ub[s], m[s] + 1), t.pyramid.beta)
    return out


def _border_units(U: int, edge: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, columns) of the U units along a tile's edge W, E, S or N (0..3), in order along it."""
    r = np.arange(U)
    return ((r, np.zeros_like(r)), (r, np.full_like(r, U - 1)), (np.zeros_like(r), r), (np.full_like(r, U - 1), r))[edge]


def _alpha_profile(fr: _Frame, key, edge: int) -> np.ndarray:
    """Own-side morph factor of the border leaves' edge midpoints along an edge, at level-0 cells."""
    levels = fr.levels[key]
    ua, ub = _border_units(levels.shape[0], edge)
    return np.repeat(_own_alpha(fr, key, levels, ua, ub), 2 << key[0])


def _tilelet_set(fr: _Frame, key, morph: bool) -> TileletSet:
    levels = fr.levels[key]
    l = key[0]
    t = fr.tiles[key]
    E = t.pyramid.effective if fr.use_effective else t.pyramid.errors
    top = t.pyramid.top
    U = levels.shape[0]
    lv = leaves_from_levels(levels)
    m = lv.level.astype(np.int64)
    ua, ub = lv.i0 // 2, lv.j0 // 2
    G = m + l
    coarser = np.zeros(len(lv), np.int32)
    finer = np.zeros(len(lv), np.int32)
    alpha = np.zeros((len(lv), 5), np.float64)
    if morph:
        parent_e = np.full(len(lv), np.inf)
        has_parent = m < top
        parent_e[has_parent] = _errors_at(E, ua[has_parent], ub[has_parent], m[has_parent] + 1)
        own = np.where(has_parent, morph_factor(t.tolerance, parent_e, t.pyramid.beta), 0.0)
        alpha[:, 4] = own
    for edge, (inside, na, nb_, along) in enumerate(_edge_neighbours(lv, U)):
        bit = EDGE_BITS[edge]
        nlev = np.full(len(lv), -1, np.int64)
        na_c, nb_c = np.clip(na, 0, U - 1), np.clip(nb_, 0, U - 1)
        nlev[inside] = levels[na_c[inside], nb_c[inside]] + l
        prof = fr.neighbour_profile(key, edge)
        cells = along.astype(np.int64) << l
        out = ~inside
        nlev[out] = prof[cells[out]]
        coarser[nlev == G + 1] |= bit
        finer[(nlev >= 0) & (nlev < G)] |= bit
        if not morph:
            continue
        a = np.zeros(len(lv))
        same = nlev == G
        # same level inside the tile: the lower of the two parents' errors, computed alike on both sides
        s_in = same & inside & (m < top)
        if np.any(s_in):
            e_nb = np.full(len(lv), np.inf)
            e_nb[s_in] = _errors_at(E, na_c[s_in], nb_c[s_in], m[s_in] + 1)
            e_min = np.minimum(parent_e, e_nb)
            a[s_in] = morph_factor(t.tolerance, e_min[s_in], t.pyramid.beta)
        # same level across a tile border: the larger of the two sides' own factors
        s_out = same & out
        if np.any(s_out):
            other = fr.neighbour_profile(key, edge, values=lambda k, e: _alpha_profile(fr, k, e))
            a[s_out] = np.maximum(own[s_out], other[cells[s_out]])
        # terrain edge (no neighbour): own parent only
        s_none = (nlev < 0)
        a[s_none] = own[s_none]
        a[(coarser & bit) != 0] = 1.0
        a[(finer & bit) != 0] = 0.0
        alpha[:, edge] = a
    return TileletSet(lv, coarser, finer, alpha.astype(np.float32), levels, l)
