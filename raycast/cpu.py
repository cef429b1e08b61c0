"""A numpy ray caster with the GPU caster's semantics (raycast/traverse.glsl), vectorized over rays, float64.

Used by the tests to check GPU hits; ``cast_tile_rays`` casts against the tile's 16-bit heights as the GPU
holds them (hybrid.tiles.quantize), ``cast_rays`` against the heights it is given. Texel space of a grid of N cells (N a power of two, (N+1)² heights):
x, y in texels (sample (i, j) at (j, i)), z in metres relative to the terrain's origin z; a ray is
P(t) = O + t D. The traversal mirrors the ray so D_x, D_y >= 0, steps texel to texel setting the crossed
coordinate exactly to the texel edge, descends the max mipmap on a possible hit and ascends when it leaves a
2x2 block (Dick et al. 3.1-3.2), and intersects the chosen reconstruction in the final cells
(``raycast.cpu_traversal``, ``raycast.cell_hits``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.tiles.quantize import quantized_heights

from .cpu_traversal import CAPPED, HIT, MISS, cast_grid, enter, step
from .options import RECONSTRUCTIONS, TRAVERSALS

__all__ = ["CAPPED", "HIT", "MISS", "RayHits", "cast_rays", "cast_tile_rays", "texel_to_world", "tile_frame"]


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


def cast_rays(
    heights,
    ext,
    zr,
    O,
    D,
    *,
    reconstruction="triangles",
    traversal="maxmip",
    tmin=0.0,
    lmin=0,
    spacing=1.0,
    lod_k=None,
    max_steps=None,
    outer=0,
    under=False,
) -> RayHits:
    """Cast rays O + t D (M x 3, texel space) through a grid of (N+1)² heights (metres) covering [0, ext] in
    x, y and zr in z; first hits with t >= tmin. spacing: metres per texel, one number or an (x, y) pair;
    lod_k = max(spacing) * K / tau turns on the LOD stop (maxmip only); outer is the mask (W 1, E 2, S 4, N 8)
    of grid sides on the terrain's boundary; under (one bool or one a ray, raycast.boundary.starts_under) marks
    rays starting under the sheet, which hit where they come up."""
    if reconstruction not in RECONSTRUCTIONS:
        raise TerrabenchError(f"reconstruction must be one of {', '.join(RECONSTRUCTIONS)}, got {reconstruction!r}")
    if traversal not in TRAVERSALS:
        raise TerrabenchError(f"traversal must be one of {', '.join(TRAVERSALS)}, got {traversal!r}")
    g = cast_grid(heights, ext, zr, reconstruction, traversal, lmin, spacing, lod_k, max_steps)
    O = np.atleast_2d(np.asarray(O, dtype=np.float64))
    D = np.atleast_2d(np.asarray(D, dtype=np.float64)).copy()
    M = len(D)
    O = np.broadcast_to(O, (M, 3)).copy()
    under = np.broadcast_to(np.asarray(under, dtype=bool), (M,))
    r, act = enter(g, O, D, float(tmin), int(outer), under)
    while act.size:
        act = step(g, r, act)
    return RayHits(r.status, r.point, r.level, r.steps)


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
    return cast_rays(h, ext, zr, O, D, tmin=near, spacing=tile.spacing_xy, outer=outer, under=under, **options)


def texel_to_world(tile, point) -> np.ndarray:
    """World positions (metres, float64) of points in a tile's texel space (x, y texels; z metres)."""
    p = np.asarray(point, dtype=np.float64)
    org = np.asarray(tile.origin, dtype=np.float64)
    sx, sy = tile.spacing_xy
    return np.stack([org[0] + p[..., 0] * sx, org[1] + p[..., 1] * sy, org[2] + p[..., 2]], -1)
