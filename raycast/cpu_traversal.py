"""The CPU ray caster's traversal (``raycast.cpu.cast_rays``): every ray's state in a cast and one step of all the
active rays at once, as raycast/traverse.glsl takes them one by one.

Texel space of a grid of N cells: rays are mirrored so D_x, D_y >= 0 and every exit is computed from the entry
point P0 (X = P0 + s D), the crossed coordinate set exactly to the texel edge. A step intersects the
reconstruction in a final cell (``raycast.cell_hits``), descends the max mipmap on a possible hit, or moves to
the cell's exit, ascending when the ray leaves a 2x2 block (Dick et al. 3.1-3.2); with the LOD stop a cell is
final once it is fine enough for the distance from the eye.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.terrain.heightfield import spacing_pair

from .cell_hits import FAR, cell_hit
from .maxmip import level_count, maxmip_levels
from .options import default_max_steps

MISS, HIT, CAPPED = 0, 1, 2


@dataclass
class CastGrid:
    """What a cast reads: the grid's heights and max mipmap (every level flattened, float64), its sizes in
    texels, the slab zr0..zr1 and the cast's options."""

    h: np.ndarray
    flat: np.ndarray
    offs: np.ndarray  # where each max-mip level starts in flat
    n: int
    ltop: int  # the coarsest level a ray climbs to
    lmin: int  # the level whose cells are intersected
    ext: np.ndarray
    zr0: float
    zr1: float
    spacing: np.ndarray
    lod_k: float | None
    lod: bool
    reconstruction: str
    traversal: str
    cap: int


@dataclass
class RayState:
    """Every ray of a cast, mirrored so D_x, D_y >= 0: the results so far and where each ray stands."""

    status: np.ndarray
    point: np.ndarray
    level: np.ndarray
    steps: np.ndarray
    P: np.ndarray  # where the ray stands, at s = sP past the entry point P0: every exit is P0 + s D
    P0: np.ndarray
    sP: np.ndarray
    D: np.ndarray
    Om: np.ndarray  # the origin, mirrored (the LOD's distances)
    lvl: np.ndarray  # the max-mip level of its cell
    moved: np.ndarray  # left its entry point
    mx: np.ndarray  # mirrored in x, in y
    my: np.ndarray
    hi_xy: np.ndarray  # the grid's far sides, mirrored
    under: np.ndarray
    no_entry_hit: np.ndarray


@dataclass
class _Cells:
    """The active rays' (indices ``act``) current cells: level ``la``, index ``ij`` (mirrored) and ``rx``, ``ry``,
    max-mip height H, far corner e, and the exit X at s = dt crossing x, y or the slab (cx, cy, cz)."""

    act: np.ndarray
    Pa: np.ndarray
    Da: np.ndarray
    P0a: np.ndarray
    la: np.ndarray
    ij: np.ndarray
    rx: np.ndarray
    ry: np.ndarray
    H: np.ndarray
    e: np.ndarray
    dt: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    cz: np.ndarray
    X: np.ndarray


def cast_grid(heights, ext, zr, reconstruction, traversal, lmin, spacing, lod_k, max_steps) -> CastGrid:
    """The grid a cast reads, with its max mipmap (``raycast.maxmip.maxmip_levels`` of the float32 heights)."""
    spacing = np.array(spacing_pair(spacing, "ray grid"))
    h32 = np.asarray(heights, dtype=np.float32)
    levels = maxmip_levels(h32)
    n = h32.shape[0] - 1
    ltop = max(level_count(n) - 2, 0)
    return CastGrid(
        h=h32.astype(np.float64),
        flat=np.concatenate([a.ravel() for a in levels]).astype(np.float64),
        offs=np.cumsum([0] + [a.size for a in levels]),
        n=n,
        ltop=ltop,
        lmin=min(int(lmin), ltop),
        ext=np.asarray(ext, dtype=np.float64),
        zr0=float(zr[0]),
        zr1=float(zr[1]),
        spacing=spacing,
        lod_k=lod_k,
        lod=lod_k is not None and traversal == "maxmip",
        reconstruction=reconstruction,
        traversal=traversal,
        cap=int(max_steps or default_max_steps(n)),
    )


def _box_entry(g: CastGrid, O, D, tmin: float):
    """(t0, entry face, entered through the top or bottom, dead) of each ray in the grid's box [0, ext] x zr:
    the face is the side's bit (W 1, E 2, S 4, N 8; 0 top, bottom or none); dead rays miss the box."""
    M = len(D)
    t0 = np.full(M, tmin)
    t1 = np.full(M, FAR)
    face = np.zeros(M, np.int64)
    zentry = np.zeros(M, bool)
    dead = np.zeros(M, bool)
    bounds = ((0.0, g.ext[0], 1, 2), (0.0, g.ext[1], 4, 8), (g.zr0, g.zr1, 0, 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        for a, (lo, hi, fpos, fneg) in enumerate(bounds):
            nz = D[:, a] != 0
            ta = (lo - O[:, a]) / D[:, a]
            tb = (hi - O[:, a]) / D[:, a]
            tn, tf = np.minimum(ta, tb), np.maximum(ta, tb)
            upd = nz & (tn > t0)
            t0 = np.where(upd, tn, t0)
            face = np.where(upd, np.where(D[:, a] > 0, fpos, fneg), face)
            zentry = np.where(upd, a == 2, zentry)
            t1 = np.where(nz, np.minimum(t1, tf), t1)
            dead |= ~nz & ((O[:, a] < lo) | (O[:, a] > hi))
    return t0, face, zentry, dead | (t0 > t1)


def enter(g: CastGrid, O, D, tmin: float, outer: int, under) -> tuple[RayState, np.ndarray]:
    """Every ray at its entry into the grid's box, mirrored so D_x, D_y >= 0 (D in place); the rays that enter."""
    M, n, ext = len(D), g.n, g.ext
    t0, face, zentry, dead = _box_entry(g, O, D, tmin)
    # a ray on the wrong side of the surface where it enters is no hit there through an outer side, nor
    # (under) through the top or at tmin; through an interior side it is a wall (traverse.glsl)
    no_entry_hit = ((face & outer) != 0) | (under & (face == 0) & ~(zentry & (D[:, 2] > 0)))
    P = O + t0[:, None] * D
    # entered through the bottom or top face: exactly on it, so rounding cannot put it outside the slab
    P[:, 2] = np.where(zentry, np.where(D[:, 2] > 0, g.zr0, g.zr1), P[:, 2])
    mx, my = D[:, 0] < 0, D[:, 1] < 0
    Om = O.copy()
    P[:, 0] = np.where(mx, n - P[:, 0], P[:, 0])
    P[:, 1] = np.where(my, n - P[:, 1], P[:, 1])
    Om[:, 0] = np.where(mx, n - O[:, 0], O[:, 0])
    Om[:, 1] = np.where(my, n - O[:, 1], O[:, 1])
    D[:, 0] = np.abs(D[:, 0])
    D[:, 1] = np.abs(D[:, 1])
    lo_xy = np.stack([np.where(mx, n - ext[0], 0.0), np.where(my, n - ext[1], 0.0)], 1)
    hi_xy = np.stack([np.where(mx, float(n), ext[0]), np.where(my, float(n), ext[1])], 1)
    P[:, :2] = np.clip(P[:, :2], lo_xy, hi_xy)
    # rays under the sheet step every lmin texel (no ascent, no LOD), as traverse.glsl
    lvl = np.where(under | (g.traversal == "naive"), g.lmin, g.ltop).astype(np.int64)
    rays = RayState(
        status=np.zeros(M, np.int8),
        point=np.full((M, 3), np.nan),
        level=np.zeros(M, np.int64),
        steps=np.zeros(M, np.int64),
        P=P,
        P0=P.copy(),
        sP=np.zeros(M),
        D=D,
        Om=Om,
        lvl=lvl,
        moved=np.zeros(M, bool),
        mx=mx,
        my=my,
        hi_xy=hi_xy,
        under=under,
        no_entry_hit=no_entry_hit,
    )
    return rays, np.nonzero(~dead)[0]


def step(g: CastGrid, r: RayState, act: np.ndarray) -> np.ndarray:
    """One step of the active rays (indices ``act``): intersect a final cell, descend a level, or move on to the
    cell's exit; the rays still active after it."""
    capped = r.steps[act] >= g.cap
    r.status[act[capped]] = CAPPED
    act = act[~capped]
    Pa, Da = r.P[act], r.D[act]
    out = (Pa[:, 0] >= r.hi_xy[act, 0]) | (Pa[:, 1] >= r.hi_xy[act, 1]) | ((Da[:, 2] >= 0) & (Pa[:, 2] > g.zr1))
    act = act[~out]
    if not act.size:
        return act
    r.steps[act] += 1
    c = _cells(g, r, act)
    boxhit = np.where(c.Da[:, 2] >= 0, c.Pa[:, 2] <= c.H, c.X[:, 2] <= c.H)
    fin = c.la <= g.lmin
    if g.lod:
        fin = fin | _lod_final(c.la, c.ij, c.H, r.Om[act], g.zr0, g.spacing, g.lod_k)
    desc = boxhit & ~fin
    done_hit, done_miss = _test_cells(g, r, c, boxhit & fin)
    la = _descend(r, c, desc)
    la, left = _advance(g, r, c, la, ~desc & ~done_hit & ~done_miss)
    done_miss |= left
    r.lvl[act] = la
    return act[~done_hit & ~done_miss]


def _cells(g: CastGrid, r: RayState, act: np.ndarray) -> _Cells:
    """The active rays' cells (climbing while the LOD allows) and where each ray leaves its cell."""
    Pa, Da = r.P[act], r.D[act]
    la = r.lvl[act]
    s = np.exp2(la.astype(np.float64))
    ij = np.floor(Pa[:, :2] / s[:, None])
    nl = g.n >> la
    amx, amy = r.mx[act], r.my[act]
    if g.lod:
        la, s, ij, nl = _lod_ascent(g, r, act, la, s, ij, nl)
    rx = np.where(amx, nl - 1 - ij[:, 0], ij[:, 0]).astype(np.int64)
    ry = np.where(amy, nl - 1 - ij[:, 1], ij[:, 1]).astype(np.int64)
    H = g.flat[g.offs[la] + ry * nl + rx]
    e = (ij + 1.0) * s[:, None]
    P0a = r.P0[act]
    with np.errstate(divide="ignore", invalid="ignore"):
        dtx = np.where(Da[:, 0] > 0, (e[:, 0] - P0a[:, 0]) / Da[:, 0], FAR)
        dty = np.where(Da[:, 1] > 0, (e[:, 1] - P0a[:, 1]) / Da[:, 1], FAR)
        dtz = np.where(
            Da[:, 2] < 0, (g.zr0 - P0a[:, 2]) / Da[:, 2], np.where(Da[:, 2] > 0, (g.zr1 - P0a[:, 2]) / Da[:, 2], FAR)
        )
    dt = np.maximum(np.minimum(np.minimum(dtx, dty), dtz), r.sP[act])
    cx, cy, cz = dtx <= dt, dty <= dt, dtz <= dt
    X = P0a + dt[:, None] * Da
    X[:, 0] = np.where(cx, e[:, 0], X[:, 0])
    X[:, 1] = np.where(cy, e[:, 1], X[:, 1])
    X[:, 2] = np.where(cz, np.where(Da[:, 2] < 0, g.zr0, g.zr1), X[:, 2])
    return _Cells(act, Pa, Da, P0a, la, ij, rx, ry, H, e, dt, cx, cy, cz, X)


def _lod_ascent(g: CastGrid, r: RayState, act: np.ndarray, la, s, ij, nl) -> tuple:
    """(la, s, ij, nl) of the active rays' cells, each climbed while its parent still meets the LOD's bound
    (not for rays under the sheet)."""
    amx, amy = r.mx[act], r.my[act]
    while True:
        can = (la < g.ltop) & ~r.under[act]
        pij = np.floor(ij * 0.5)
        pnl = nl >> 1
        prx = np.where(amx, pnl - 1 - pij[:, 0], pij[:, 0]).astype(np.int64)
        pry = np.where(amy, pnl - 1 - pij[:, 1], pij[:, 1]).astype(np.int64)
        lp = np.minimum(la + 1, g.ltop + 1)
        PH = g.flat[g.offs[lp] + np.clip(pry, 0, None) * np.maximum(pnl, 1) + np.clip(prx, 0, None)]
        up = can & _lod_final(la + 1, pij, PH, r.Om[act], g.zr0, g.spacing, g.lod_k)
        if not up.any():
            return la, s, ij, nl
        la = np.where(up, la + 1, la)
        s = np.where(up, s * 2, s)
        ij = np.where(up[:, None], pij, ij)
        nl = np.where(up, pnl, nl)


def _test_cells(g: CastGrid, r: RayState, c: _Cells, test: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(hit, miss) masks of the active rays: those in ``test`` intersect the reconstruction in their final cell
    (``cell_hit``, unmirrored); their hits are recorded in ``r``."""
    done_hit = np.zeros(len(c.act), bool)
    done_miss = np.zeros(len(c.act), bool)
    if not test.any():
        return done_hit, done_miss
    n, act = g.n, c.act
    ti = np.nonzero(test)[0]
    amx, amy = r.mx[act[ti]], r.my[act[ti]]
    A, B = c.Pa[ti].copy(), c.X[ti].copy()
    A[:, 0] = np.where(amx, n - A[:, 0], A[:, 0])
    B[:, 0] = np.where(amx, n - B[:, 0], B[:, 0])
    A[:, 1] = np.where(amy, n - A[:, 1], A[:, 1])
    B[:, 1] = np.where(amy, n - B[:, 1], B[:, 1])
    S = (1 << c.la[ti]).astype(np.int64)
    cx0, cy0 = c.rx[ti] * S, c.ry[ti] * S
    h = g.h
    hc = np.stack([h[cy0, cx0], h[cy0, cx0 + S], h[cy0 + S, cx0], h[cy0 + S, cx0 + S]], 1)
    # a ray under the sheet crosses it upward: the same test with heights and ray z mirrored
    sg = np.where(r.under[act[ti]], -1.0, 1.0)
    Am, Bm = A.copy(), B.copy()
    Am[:, 2] *= sg
    Bm[:, 2] *= sg
    u = cell_hit(
        g.reconstruction,
        Am,
        Bm,
        np.stack([cx0, cy0], 1).astype(np.float64),
        S.astype(np.float64),
        hc * sg[:, None],
        c.H[ti] * sg,
    )
    got = u >= 0
    gi = ti[got]
    ug = u[got]
    Q = A[got] + ug[:, None] * (B[got] - A[got])
    outer_miss = (ug == 0) & r.no_entry_hit[act[gi]] & ~r.moved[act[gi]]
    pad_miss = (Q[:, 0] > g.ext[0] + 1e-4) | (Q[:, 1] > g.ext[1] + 1e-4)
    Q[:, 0] = np.clip(Q[:, 0], 0, g.ext[0])
    Q[:, 1] = np.clip(Q[:, 1], 0, g.ext[1])
    ok = ~outer_miss & ~pad_miss
    done_hit[gi[ok]] = True
    done_miss[gi[~ok]] = True
    r.status[act[gi[ok]]] = HIT
    r.point[act[gi[ok]]] = Q[ok]
    r.level[act[gi[ok]]] = c.la[gi[ok]]
    return done_hit, done_miss


def _descend(r: RayState, c: _Cells, desc: np.ndarray) -> np.ndarray:
    """The active rays' levels, one lower for those in ``desc``, each moved first to where it comes down to its
    cell's max-mip height (if that lies ahead)."""
    if not desc.any():
        return c.la
    act = c.act
    di = np.nonzero(desc)[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        sa = np.where(c.Da[di, 2] < 0, (c.H[di] - c.P0a[di, 2]) / c.Da[di, 2], -FAR)
    go = sa > r.sP[act[di]]
    gi = di[go]
    Pd = c.P0a[gi] + sa[go][:, None] * c.Da[gi]
    Pd[:, :2] = np.minimum(Pd[:, :2], c.e[gi])
    r.P[act[gi]] = Pd
    r.sP[act[gi]] = sa[go]
    r.moved[act[gi]] = True
    la = c.la.copy()
    la[di] -= 1
    return la


def _advance(g: CastGrid, r: RayState, c: _Cells, la: np.ndarray, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(levels, left): the active rays in ``rest`` move to their cell's exit, a level up (maxmip) where they leave
    a 2x2 block (Dick et al. 3.2), except those leaving through the slab's top or bottom (``left``: misses)."""
    left = rest & c.cz
    ri = np.nonzero(rest & ~c.cz)[0]
    act = c.act
    r.P[act[ri]] = c.X[ri]
    r.sP[act[ri]] = c.dt[ri]
    r.moved[act[ri]] = True
    if g.traversal == "maxmip":
        upx = c.cx[ri] & (((c.ij[ri, 0].astype(np.int64) + 1) & 1) == 0)
        upy = c.cy[ri] & (((c.ij[ri, 1].astype(np.int64) + 1) & 1) == 0)
        la = la.copy()
        la[ri] = np.where((upx | upy) & ~r.under[act[ri]], np.minimum(la[ri] + 1, g.ltop), la[ri])
    return la, left


def _lod_final(l, ij, H, Om, zlo, spacing, lod_k):
    s = np.exp2(l.astype(np.float64))
    lo = ij * s[:, None]
    hi = lo + s[:, None]
    dxy = np.maximum(np.maximum(lo - Om[:, :2], Om[:, :2] - hi), 0.0) * spacing
    dz = np.maximum(np.maximum(zlo - Om[:, 2], Om[:, 2] - H), 0.0)
    return s * lod_k <= np.sqrt((dxy**2).sum(axis=1) + dz**2)
