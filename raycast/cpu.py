"""A numpy ray caster with the GPU caster's semantics (raycast/traverse.glsl), vectorized over rays, float64.

Used by the tests to check GPU hits; ``cast_tile_rays`` casts against the tile's 16-bit heights as the GPU
holds them (hybrid.tiles.quantize), ``cast_rays`` against the heights it is given. Texel space of a grid of N cells (N a power of two, (N+1)² heights):
x, y in texels (sample (i, j) at (j, i)), z in metres relative to the terrain's origin z; a ray is
P(t) = O + t D. The traversal mirrors the ray so D_x, D_y >= 0, steps texel to texel setting the crossed
coordinate exactly to the texel edge, descends the max mipmap on a possible hit and ascends when it leaves a
2x2 block (Dick et al. 3.1-3.2), and intersects the chosen reconstruction in the final cells.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import spacing_pair
from hybrid.tiles.quantize import quantized_heights

from .maxmip import level_count, maxmip_levels
from .options import RECONSTRUCTIONS, TRAVERSALS, default_max_steps

MISS, HIT, CAPPED = 0, 1, 2
FAR = 1e30


@dataclass
class RayHits:
    """Result per ray: status (0 miss, 1 hit, 2 capped), hit point (real texel x, y; z metres; NaN if none),
    max-mip level of the final cell, texels visited."""

    status: np.ndarray
    point: np.ndarray
    level: np.ndarray
    steps: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        """True where the ray hit the surface."""
        return self.status == HIT


# --- reconstructions: first hit u in [0, 1] on segment A -> B in a cell, or -1 -------------------------
def _bilin(hc, f):
    return (hc[:, 0] * (1 - f[:, 0]) + hc[:, 1] * f[:, 0]) * (1 - f[:, 1]) + \
           (hc[:, 2] * (1 - f[:, 0]) + hc[:, 3] * f[:, 0]) * f[:, 1]


def _tri(hc, f, lower):
    lo = hc[:, 0] + f[:, 0] * (hc[:, 1] - hc[:, 0]) + f[:, 1] * (hc[:, 3] - hc[:, 1])
    up = hc[:, 0] + f[:, 1] * (hc[:, 2] - hc[:, 0]) + f[:, 0] * (hc[:, 3] - hc[:, 2])
    return np.where(lower, lo, up)


def cell_hit(recon: str, A, B, c0, S, hc, H) -> np.ndarray:
    """Fraction u of the first hit on segments A -> B (k x 3, real texel space) in cells with corner c0 (k x 2),
    size S (k), corner heights hc (k x 4: h00, h01 east, h10 north, h11) and max-mip height H (k); -1 if none."""
    with np.errstate(divide="ignore", invalid="ignore"):
        if recon == "planes":
            return np.where(A[:, 2] <= H, 0.0, np.where(B[:, 2] <= H, (H - A[:, 2]) / (B[:, 2] - A[:, 2]), -1.0))
        fa = (A[:, :2] - c0) / S[:, None]
        fb = (B[:, :2] - c0) / S[:, None]
        if recon == "linear":
            d1 = A[:, 2] - _bilin(hc, fa)
            d2 = B[:, 2] - _bilin(hc, fb)
            return np.where(d1 <= 0, 0.0, np.where(d2 <= 0, d1 / (d1 - d2), -1.0))
        if recon == "triangles":
            ga, gb = fa[:, 0] - fa[:, 1], fb[:, 0] - fb[:, 1]
            ud = np.where(ga * gb < 0, ga / (ga - gb), 1.0)
            lower = ga + (gb - ga) * (0.5 * ud) >= 0
            d0 = A[:, 2] - _tri(hc, fa, lower)
            fd = fa + (fb - fa) * ud[:, None]
            zd = A[:, 2] + (B[:, 2] - A[:, 2]) * ud
            dd = zd - _tri(hc, fd, lower)
            dd2 = zd - _tri(hc, fd, ~lower)
            d1 = B[:, 2] - _tri(hc, fb, ~lower)
            second = np.where(dd2 <= 0, ud, np.where(d1 <= 0, ud + (1 - ud) * dd2 / (dd2 - d1), -1.0))
            second = np.where(ud < 1.0, second, -1.0)
            return np.where(d0 <= 0, 0.0, np.where(dd <= 0, ud * d0 / (d0 - dd), second))
        if recon == "bilinear":
            df = fb - fa
            a = hc[:, 1] - hc[:, 0]
            b = hc[:, 2] - hc[:, 0]
            c = hc[:, 0] - hc[:, 1] - hc[:, 2] + hc[:, 3]
            c0 = A[:, 2] - (hc[:, 0] + a * fa[:, 0] + b * fa[:, 1] + c * fa[:, 0] * fa[:, 1])
            c1 = (B[:, 2] - A[:, 2]) - (a * df[:, 0] + b * df[:, 1] + c * (fa[:, 0] * df[:, 1] + fa[:, 1] * df[:, 0]))
            c2 = -c * df[:, 0] * df[:, 1]
            dend = c0 + c1 + c2
            lin = np.abs(c2) <= 1e-6 * (np.abs(c1) + np.abs(c0))
            u_lin = np.where(dend <= 0, c0 / (c0 - dend), -1.0)
            disc = c1 * c1 - 4 * c2 * c0
            sq = np.sqrt(np.maximum(disc, 0.0))
            q = -0.5 * (c1 + np.where(c1 >= 0, sq, -sq))
            r1 = q / c2
            r2 = np.where(q != 0, c0 / q, FAR)
            u = np.full(len(c0), FAR)
            u = np.where((r1 >= 0) & (r1 <= 1), r1, u)
            u = np.where((r2 >= 0) & (r2 <= 1), np.minimum(u, r2), u)
            u_q = np.where(u <= 1, u, np.where(dend <= 0, 1.0, -1.0))
            u_q = np.where(disc < 0, -1.0, u_q)
            return np.where(c0 <= 0, 0.0, np.where(lin, u_lin, u_q))
    raise TerrabenchError(f"reconstruction must be one of {', '.join(RECONSTRUCTIONS)}, got {recon!r}")


def _lod_final(l, ij, H, Om, zlo, spacing, lod_k):
    s = np.exp2(l.astype(np.float64))
    lo = ij * s[:, None]
    hi = lo + s[:, None]
    dxy = np.maximum(np.maximum(lo - Om[:, :2], Om[:, :2] - hi), 0.0) * spacing
    dz = np.maximum(np.maximum(zlo - Om[:, 2], Om[:, 2] - H), 0.0)
    return s * lod_k <= np.sqrt((dxy ** 2).sum(axis=1) + dz ** 2)


def cast_rays(heights, ext, zr, O, D, *, reconstruction="triangles", traversal="maxmip", tmin=0.0, lmin=0,
              spacing=1.0, lod_k=None, max_steps=None, outer=0, under=False) -> RayHits:
    """Cast rays O + t D (M x 3, texel space) through a grid of (N+1)² heights (metres) covering [0, ext] in
    x, y and zr in z; first hits with t >= tmin. spacing: metres per texel, one number or an (x, y) pair;
    lod_k = max(spacing) * K / tau turns on the LOD stop (maxmip only); outer is the mask (W 1, E 2, S 4, N 8)
    of grid sides on the terrain's boundary; under (one bool or one a ray, raycast.boundary.starts_under) marks
    rays starting under the sheet, which hit where they come up."""
    if reconstruction not in RECONSTRUCTIONS:
        raise TerrabenchError(f"reconstruction must be one of {', '.join(RECONSTRUCTIONS)}, got {reconstruction!r}")
    if traversal not in TRAVERSALS:
        raise TerrabenchError(f"traversal must be one of {', '.join(TRAVERSALS)}, got {traversal!r}")
    spacing = np.array(spacing_pair(spacing, "ray grid"))
    h32 = np.asarray(heights, dtype=np.float32)
    levels = maxmip_levels(h32)
    h = h32.astype(np.float64)
    n = h.shape[0] - 1
    ltop = max(level_count(n) - 2, 0)
    lmin = min(int(lmin), ltop)
    offs = np.cumsum([0] + [a.size for a in levels])
    flat = np.concatenate([a.ravel() for a in levels]).astype(np.float64)
    O = np.atleast_2d(np.asarray(O, dtype=np.float64))
    D = np.atleast_2d(np.asarray(D, dtype=np.float64)).copy()
    M = len(D)
    O = np.broadcast_to(O, (M, 3)).copy()
    under = np.broadcast_to(np.asarray(under, dtype=bool), (M,))
    ext = np.asarray(ext, dtype=np.float64)
    zr0, zr1 = float(zr[0]), float(zr[1])
    cap = int(max_steps or default_max_steps(n))
    lod = lod_k is not None and traversal == "maxmip"

    status = np.zeros(M, np.int8)
    point = np.full((M, 3), np.nan)
    level = np.zeros(M, np.int64)
    steps = np.zeros(M, np.int64)

    # entry into the box
    t0 = np.full(M, float(tmin))
    t1 = np.full(M, FAR)
    face = np.zeros(M, np.int64)
    zentry = np.zeros(M, bool)
    dead = np.zeros(M, bool)
    bounds = ((0.0, ext[0], 1, 2), (0.0, ext[1], 4, 8), (zr0, zr1, 0, 0))
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
    dead |= t0 > t1
    # a ray on the wrong side of the surface where it enters is no hit there through an outer side, nor
    # (under) through the top or at tmin; through an interior side it is a wall (traverse.glsl)
    no_entry_hit = ((face & int(outer)) != 0) | (under & (face == 0) & ~(zentry & (D[:, 2] > 0)))
    P = O + t0[:, None] * D
    # entered through the bottom or top face: exactly on it, so rounding cannot put it outside the slab
    P[:, 2] = np.where(zentry, np.where(D[:, 2] > 0, zr0, zr1), P[:, 2])
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
    P0 = P.copy()          # every exit is computed from the entry point: X = P0 + s D
    sP = np.zeros(M)
    # rays under the sheet step every lmin texel (no ascent, no LOD), as traverse.glsl
    lvl = np.where(under | (traversal == "naive"), lmin, ltop).astype(np.int64)
    moved = np.zeros(M, bool)
    act = np.nonzero(~dead)[0]

    while act.size:
        capped = steps[act] >= cap
        status[act[capped]] = CAPPED
        act = act[~capped]
        Pa, Da = P[act], D[act]
        out = (Pa[:, 0] >= hi_xy[act, 0]) | (Pa[:, 1] >= hi_xy[act, 1]) | ((Da[:, 2] >= 0) & (Pa[:, 2] > zr1))
        act, Pa, Da = act[~out], Pa[~out], Da[~out]
        if not act.size:
            break
        steps[act] += 1
        la = lvl[act]
        s = np.exp2(la.astype(np.float64))
        ij = np.floor(Pa[:, :2] / s[:, None])
        nl = n >> la
        amx, amy = mx[act], my[act]
        if lod:
            while True:
                can = (la < ltop) & ~under[act]
                pij = np.floor(ij * 0.5)
                pnl = nl >> 1
                prx = np.where(amx, pnl - 1 - pij[:, 0], pij[:, 0]).astype(np.int64)
                pry = np.where(amy, pnl - 1 - pij[:, 1], pij[:, 1]).astype(np.int64)
                lp = np.minimum(la + 1, ltop + 1)
                PH = flat[offs[lp] + np.clip(pry, 0, None) * np.maximum(pnl, 1) + np.clip(prx, 0, None)]
                up = can & _lod_final(la + 1, pij, PH, Om[act], zr0, spacing, lod_k)
                if not up.any():
                    break
                la = np.where(up, la + 1, la)
                s = np.where(up, s * 2, s)
                ij = np.where(up[:, None], pij, ij)
                nl = np.where(up, pnl, nl)
        rx = np.where(amx, nl - 1 - ij[:, 0], ij[:, 0]).astype(np.int64)
        ry = np.where(amy, nl - 1 - ij[:, 1], ij[:, 1]).astype(np.int64)
        H = flat[offs[la] + ry * nl + rx]
        e = (ij + 1.0) * s[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            P0a = P0[act]
            dtx = np.where(Da[:, 0] > 0, (e[:, 0] - P0a[:, 0]) / Da[:, 0], FAR)
            dty = np.where(Da[:, 1] > 0, (e[:, 1] - P0a[:, 1]) / Da[:, 1], FAR)
            dtz = np.where(Da[:, 2] < 0, (zr0 - P0a[:, 2]) / Da[:, 2], np.where(Da[:, 2] > 0, (zr1 - P0a[:, 2]) / Da[:, 2], FAR))
        dt = np.maximum(np.minimum(np.minimum(dtx, dty), dtz), sP[act])
        cx, cy, cz = dtx <= dt, dty <= dt, dtz <= dt
        X = P0a + dt[:, None] * Da
        X[:, 0] = np.where(cx, e[:, 0], X[:, 0])
        X[:, 1] = np.where(cy, e[:, 1], X[:, 1])
        X[:, 2] = np.where(cz, np.where(Da[:, 2] < 0, zr0, zr1), X[:, 2])
        boxhit = np.where(Da[:, 2] >= 0, Pa[:, 2] <= H, X[:, 2] <= H)
        fin = la <= lmin
        if lod:
            fin = fin | _lod_final(la, ij, H, Om[act], zr0, spacing, lod_k)
        desc = boxhit & ~fin
        test = boxhit & fin
        done_hit = np.zeros(len(act), bool)
        done_miss = np.zeros(len(act), bool)
        if test.any():
            ti = np.nonzero(test)[0]
            A, B = Pa[ti].copy(), X[ti].copy()
            A[:, 0] = np.where(amx[ti], n - A[:, 0], A[:, 0])
            B[:, 0] = np.where(amx[ti], n - B[:, 0], B[:, 0])
            A[:, 1] = np.where(amy[ti], n - A[:, 1], A[:, 1])
            B[:, 1] = np.where(amy[ti], n - B[:, 1], B[:, 1])
            S = (1 << la[ti]).astype(np.int64)
            cx0, cy0 = rx[ti] * S, ry[ti] * S
            hc = np.stack([h[cy0, cx0], h[cy0, cx0 + S], h[cy0 + S, cx0], h[cy0 + S, cx0 + S]], 1)
            # a ray under the sheet crosses it upward: the same test with heights and ray z mirrored
            sg = np.where(under[act[ti]], -1.0, 1.0)
            Am, Bm = A.copy(), B.copy()
            Am[:, 2] *= sg
            Bm[:, 2] *= sg
            u = cell_hit(reconstruction, Am, Bm, np.stack([cx0, cy0], 1).astype(np.float64), S.astype(np.float64),
                         hc * sg[:, None], H[ti] * sg)
            got = u >= 0
            gi = ti[got]
            ug = u[got]
            Q = A[got] + ug[:, None] * (B[got] - A[got])
            outer_miss = (ug == 0) & no_entry_hit[act[gi]] & ~moved[act[gi]]
            pad_miss = (Q[:, 0] > ext[0] + 1e-4) | (Q[:, 1] > ext[1] + 1e-4)
            Q[:, 0] = np.clip(Q[:, 0], 0, ext[0])
            Q[:, 1] = np.clip(Q[:, 1], 0, ext[1])
            ok = ~outer_miss & ~pad_miss
            done_hit[gi[ok]] = True
            done_miss[gi[~ok]] = True
            status[act[gi[ok]]] = HIT
            point[act[gi[ok]]] = Q[ok]
            level[act[gi[ok]]] = la[gi[ok]]
        # descend
        if desc.any():
            di = np.nonzero(desc)[0]
            with np.errstate(divide="ignore", invalid="ignore"):
                sa = np.where(Da[di, 2] < 0, (H[di] - P0a[di, 2]) / Da[di, 2], -FAR)
            go = sa > sP[act[di]]
            gi = di[go]
            Pd = P0a[gi] + sa[go][:, None] * Da[gi]
            Pd[:, :2] = np.minimum(Pd[:, :2], e[gi])
            P[act[gi]] = Pd
            sP[act[gi]] = sa[go]
            moved[act[gi]] = True
            la = la.copy()
            la[di] -= 1
        # advance the rest to the texel exit
        rest = ~desc & ~done_hit & ~done_miss
        done_miss |= rest & cz
        rest &= ~cz
        ri = np.nonzero(rest)[0]
        P[act[ri]] = X[ri]
        sP[act[ri]] = dt[ri]
        moved[act[ri]] = True
        if traversal == "maxmip":
            upx = cx[ri] & (((ij[ri, 0].astype(np.int64) + 1) & 1) == 0)
            upy = cy[ri] & (((ij[ri, 1].astype(np.int64) + 1) & 1) == 0)
            la = la.copy()
            la[ri] = np.where((upx | upy) & ~under[act[ri]], np.minimum(la[ri] + 1, ltop), la[ri])
        lvl[act] = la
        act = act[~done_hit & ~done_miss]
    return RayHits(status, point, level, steps)


def tile_frame(tile, eye, dirs):
    """Ray origin and directions of world rays (eye + t dirs) in a tile's texel space, with its ext and zr.

    x and y are divided by the tile's spacing_x and spacing_y (z stays metres), so t is the world ray parameter.
    """
    sx, sy = tile.spacing_xy
    org = np.asarray(tile.origin, dtype=np.float64)
    e = np.asarray(eye, dtype=np.float64) - org
    O = np.array([e[0] / sx, e[1] / sy, e[2]])
    d = np.atleast_2d(np.asarray(dirs, dtype=np.float64))
    D = np.stack([d[:, 0] / sx, d[:, 1] / sy, d[:, 2]], 1)
    x0, y0, x1, y1 = (float(v) for v in tile.clip)
    ext = ((x1 - x0) / sx, (y1 - y0) / sy)
    zr = (float(tile.zmin) - org[2], float(tile.zmax) - org[2])
    return O, D, ext, zr


def cast_tile_rays(tile, eye, dirs, *, near=0.0, outer=0, under=False, **options) -> RayHits:
    """Cast world rays (eye + t dirs, t >= near) against one tile's heights as the GPU holds them (16-bit,
    hybrid.tiles.quantize); options as cast_rays. Points in tile texels."""
    O, D, ext, zr = tile_frame(tile, eye, dirs)
    h = quantized_heights(tile.heights, getattr(tile, "source_step", None))
    return cast_rays(h, ext, zr, O, D, tmin=near, spacing=tile.spacing_xy, outer=outer, under=under,
                     **options)


def texel_to_world(tile, point) -> np.ndarray:
    """World positions (metres, float64) of points in a tile's texel space (x, y texels; z metres)."""
    p = np.asarray(point, dtype=np.float64)
    org = np.asarray(tile.origin, dtype=np.float64)
    sx, sy = tile.spacing_xy
    return np.stack([org[0] + p[..., 0] * sx, org[1] + p[..., 1] * sy, org[2] + p[..., 2]], -1)
