"""What each tile of a restricted frame draws (``raster.restriction.restrict_frame``): its leaves, the edges whose
neighbour is coarser (midpoints dropped) or finer, the morph factors of edge midpoints and centres, and the lean
drops of the GPU selection's lean leaves.

Functions of the frame pass's state (``raster.restriction``: its tiles, their solved leaf levels and the
neighbours' profiles along each edge), with the per-leaf helpers it shares.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .morph import morph_factor, turn_factor
from .quadtree import Leaves, leaves_from_levels

EDGE_W, EDGE_E, EDGE_S, EDGE_N = 1, 2, 4, 8
EDGE_BITS = (EDGE_W, EDGE_E, EDGE_S, EDGE_N)
OPPOSITE = (1, 0, 3, 2)


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


def lean_set(fr, key, ts: TileletSet, morph: bool, exact_full_resolution: bool = True) -> TileletSet:
    """The set with its lean drops (``restrict_frame``): midpoints of edges whose leaves' lean factors are 1."""
    t = fr.tiles[key]
    E = t.pyramid.effective if fr.use_effective else t.pyramid.errors
    beta = t.pyramid.beta
    lv, U = ts.leaves, ts.level_map.shape[0]
    m = lv.level.astype(np.int64)
    ua, ub = lv.i0 // 2, lv.j0 // 2

    def factor(a, b, level, side):
        e = errors_at(E, a, b, level)
        if t.pyramid.sides:  # the side's own stitched error, where larger
            e = np.maximum(e, errors_at([d[side] for d in t.pyramid.sides], a, b, level))
        with np.errstate(divide="ignore"):
            r = np.where(e > 0, t.tolerance / np.where(e > 0, e, 1.0), np.inf)
        if not morph:  # level-0 leaves may exceed the tolerance: kept
            f = (r >= 1.0).astype(np.float64)
        else:
            f = np.clip((r - 1.0) / (1.0 / beta - 1.0), 0.0, 1.0)
        if not exact_full_resolution:
            return f
        return np.where((level == 0) & (key[0] == 0), 0.0, f)  # full resolution keeps the reference's cells

    dropped = ts.coarser.copy()
    am = np.zeros((len(lv), 4))
    for edge, (inside, na, nb_, along) in enumerate(edge_neighbours(lv, U)):
        bit = EDGE_BITS[edge]
        own = factor(ua, ub, m, edge)
        na_c, nb_c = np.clip(na, 0, U - 1), np.clip(nb_, 0, U - 1)
        same = inside & (ts.level_map[na_c, nb_c] == m)
        le = np.zeros(len(lv))
        le[same] = np.minimum(own[same], factor(na_c[same], nb_c[same], m[same], OPPOSITE[edge]))
        edge_of_terrain = (
            ~inside & ((ts.finer & bit) == 0) & (fr.neighbour_profile(key, edge)[along.astype(np.int64) << key[0]] < 0)
        )
        le[edge_of_terrain] = own[edge_of_terrain]
        am[:, edge] = np.maximum(ts.morph[:, edge], le)
        dropped[np.maximum(ts.morph[:, edge], le) >= 1.0] |= bit
    if exact_full_resolution:
        return replace(ts, dropped=dropped)
    level0 = m == 0  # edges W, E, S, N: the SE cell's are E and S, the NW's W and N
    turns = np.column_stack(
        [
            np.where(level0 & (dropped & 6 == 0), turn_factor(np.maximum(am[:, 1], am[:, 2])), 0.0),
            np.where(level0 & (dropped & 9 == 0), turn_factor(np.maximum(am[:, 0], am[:, 3])), 0.0),
        ]
    )
    return replace(ts, dropped=dropped, turns=turns)


def errors_at(E, a: np.ndarray, b: np.ndarray, level: np.ndarray) -> np.ndarray:
    """Errors (metres) E[level][a >> level, b >> level] of the nodes of ``level`` covering units (a, b)."""
    out = np.zeros(len(level))
    for x in np.unique(level):
        s = level == x
        out[s] = E[x][a[s] >> x, b[s] >> x]
    return out


def edge_neighbours(lv: Leaves, U: int) -> tuple:
    """Per edge W, E, S, N of every leaf: (neighbour inside the tile, unit row and column just outside the edge,
    the leaf's border cell index along the edge, for neighbours across the tile border)."""
    ua, ub, su = lv.i0 // 2, lv.j0 // 2, 1 << lv.level.astype(np.int64)
    return (
        (ub > 0, ua, ub - 1, lv.i0),
        (ub + su < U, ua, ub + su, lv.i0),
        (ua > 0, ua - 1, ub, lv.j0),
        (ua + su < U, ua + su, ub, lv.j0),
    )


def _own_alpha(fr, key, levels: np.ndarray, ua: np.ndarray, ub: np.ndarray) -> np.ndarray:
    """Morph factor of edge midpoints from the leaf's own parent only, for units (ua, ub) (arrays)."""
    t = fr.tiles[key]
    E = t.pyramid.effective if fr.use_effective else t.pyramid.errors
    m = levels[ua, ub].astype(np.int64)
    out = np.zeros(ua.shape, dtype=np.float64)
    s = m < t.pyramid.top
    out[s] = morph_factor(t.tolerance, errors_at(E, ua[s], ub[s], m[s] + 1), t.pyramid.beta)
    return out


def border_units(U: int, edge: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, columns) of the U units along a tile's edge W, E, S or N (0..3), in order along it."""
    r = np.arange(U)
    return ((r, np.zeros_like(r)), (r, np.full_like(r, U - 1)), (np.zeros_like(r), r), (np.full_like(r, U - 1), r))[
        edge
    ]


def _alpha_profile(fr, key, edge: int) -> np.ndarray:
    """Own-side morph factor of the border leaves' edge midpoints along an edge, at level-0 cells."""
    levels = fr.levels[key]
    ua, ub = border_units(levels.shape[0], edge)
    return np.repeat(_own_alpha(fr, key, levels, ua, ub), 2 << key[0])


def tilelet_set(fr, key, morph: bool) -> TileletSet:
    """What tile ``key`` of a restricted frame ``fr`` (``raster.restriction``) draws: its leaves, the edges whose
    neighbour is coarser or finer, and (with ``morph``) the morph factors of its edge midpoints and centres."""
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
        parent_e[has_parent] = errors_at(E, ua[has_parent], ub[has_parent], m[has_parent] + 1)
        own = np.where(has_parent, morph_factor(t.tolerance, parent_e, t.pyramid.beta), 0.0)
        alpha[:, 4] = own
    for edge, (inside, na, nb_, along) in enumerate(edge_neighbours(lv, U)):
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
            e_nb[s_in] = errors_at(E, na_c[s_in], nb_c[s_in], m[s_in] + 1)
            e_min = np.minimum(parent_e, e_nb)
            a[s_in] = morph_factor(t.tolerance, e_min[s_in], t.pyramid.beta)
        # same level across a tile border: the larger of the two sides' own factors
        s_out = same & out
        if np.any(s_out):
            other = fr.neighbour_profile(key, edge, values=lambda k, e: _alpha_profile(fr, k, e))
            a[s_out] = np.maximum(own[s_out], other[cells[s_out]])
        # terrain edge (no neighbour): own parent only
        s_none = nlev < 0
        a[s_none] = own[s_none]
        a[(coarser & bit) != 0] = 1.0
        a[(finer & bit) != 0] = 0.0
        alpha[:, edge] = a
    return TileletSet(lv, coarser, finer, alpha.astype(np.float32), levels, l)
