"""First hits of ray segments in single grid cells, per reconstruction: the numpy form of raycast/traverse.glsl's
cell tests, vectorized over segments, float64 (``raycast.cpu`` calls ``cell_hit`` in each ray's final cells).

A cell of side S has corner c0 and corner heights h00, h01 (east), h10 (north) and h11; its max-mip height H
bounds them. planes: the cell's box top at H; linear: the ray's height above the bilinear surface, taken as
linear between the segment's ends; triangles: the cell's two triangles, split along its diagonal from corner
(0, 0) to (1, 1); bilinear: the bilinear patch, exactly (a quadratic along the segment).
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import TerrabenchError

from .options import RECONSTRUCTIONS

FAR = 1e30


def _bilin(hc, f):
    return (hc[:, 0] * (1 - f[:, 0]) + hc[:, 1] * f[:, 0]) * (1 - f[:, 1]) + (
        hc[:, 2] * (1 - f[:, 0]) + hc[:, 3] * f[:, 0]
    ) * f[:, 1]


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
