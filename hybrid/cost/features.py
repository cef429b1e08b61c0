"""Per-tile features known before drawing, for the cost model: footprint, triangles, ray-step proxy, level, distance."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

from hybrid.camera.view import View
from hybrid.cost.footprint import footprints
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.tiletree import SelectedTile, TileSelection


@dataclass(frozen=True)
class TileFeatures:
    """What the cost model sees of one tile in one view.

    pixels: screen area (px) of the tile's AABB projection, cut at the near plane and clipped to the viewport
      — an upper bound of the pixels either strategy shades.
    triangles: triangles the raster strategy would draw for this tile at this view.
    slab_cells: level-0-of-the-tile cells a ray crosses inside the tile's height slab at this view's
      elevation angle, (zmax - zmin) / tan(elevation) metres counted in cells along the ray's heading (cells
      spacing_x by spacing_y metres), at most the tile's diagonal; the
      maximum-mipmap traversal takes about log2(1 + slab_cells) steps more per ray as it grows.
    visible: share of those triangles inside the view frustum, in [0, 1] (the raster strategy's estimate, by
      blocks of the tile); the raster path culls tilelets outside the frustum, so its cost follows
      ``triangles * visible``.
    surface_pixels: screen area of the tile's rectangle at mid height (the surface's rough footprint): rays
      there hit and pay for shading, rays elsewhere in the box leave it early.
    """

    pixels: float
    triangles: float
    slab_cells: float
    level: int
    distance: float
    visible: float = 1.0
    surface_pixels: float = 0.0

    def as_dict(self) -> dict:
        """Plain dict of the features."""
        return asdict(self)

    @classmethod
    def from_row(cls, row: dict) -> TileFeatures:
        """The features of a tiles-table row (``TilePlan.row``: ``level`` and ``f_<name>`` columns)."""
        return cls(**{f.name: row["level"] if f.name == "level" else row[f"f_{f.name}"] for f in fields(cls)})


def _convex_hull(pts) -> list[tuple[float, float]]:
    """Counter-clockwise convex hull of 2-D points (monotone chain), collinear points dropped; fewer than three
    distinct points are returned as they are, sorted."""
    pts = sorted(set(map(tuple, pts)))
    if len(pts) < 3:
        return pts

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    upper: list[tuple[float, float]] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def _hull_area_clipped(pts: np.ndarray, w: float, h: float) -> float:
    """Area of the convex hull of 2-D points clipped to the rectangle [0, w] x [0, h]."""
    poly = _convex_hull(np.round(pts, 6))
    if len(poly) < 3:
        return 0.0
    for axis, bound, keep_less in ((0, 0.0, False), (0, w, True), (1, 0.0, False), (1, h, True)):
        out = []
        for i, cur in enumerate(poly):
            prev = poly[i - 1]
            cin = cur[axis] <= bound if keep_less else cur[axis] >= bound
            pin = prev[axis] <= bound if keep_less else prev[axis] >= bound
            if cin != pin:
                t = (bound - prev[axis]) / (cur[axis] - prev[axis])
                out.append((prev[0] + t * (cur[0] - prev[0]), prev[1] + t * (cur[1] - prev[1])))
            if cin:
                out.append(cur)
        poly = out
        if not poly:
            return 0.0
    x = np.array([p[0] for p in poly])
    y = np.array([p[1] for p in poly])
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


_BOX_EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]


def footprint_pixels(view: View, lo: np.ndarray, hi: np.ndarray) -> float:
    """Screen area in pixels of a world AABB's projection, clipped to the near plane and the viewport.

    The box cut by the near plane is a convex polyhedron; its projection is the convex hull of its projected
    vertices: the corners in front of the plane and the points where box edges cross it.
    """
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    rel = (corners - view.eye) @ view.rotation().T  # eye space, camera looks down -z
    depth = -rel[:, 2]
    near = view.near * (1 + 1e-9)
    pts = [rel[i] for i in range(8) if depth[i] >= near]
    for a, b in _BOX_EDGES:
        if (depth[a] - near) * (depth[b] - near) < 0:
            t = (near - depth[a]) / (depth[b] - depth[a])
            pts.append(rel[a] + t * (rel[b] - rel[a]))
    if len(pts) < 3:
        return 0.0
    front = np.array(pts)
    t = view.tan_half_fov
    x = (front[:, 0] / -front[:, 2]) / (t * view.aspect)
    y = (front[:, 1] / -front[:, 2]) / t
    screen = np.stack([(x + 1) * 0.5 * view.width, (1 - y) * 0.5 * view.height], axis=1)
    return _hull_area_clipped(screen, view.width, view.height)


def slab_cells(view: View, lo: np.ndarray, hi: np.ndarray, spacing_xy, n: int) -> float:
    """Cells (of the tile's (x, y) spacing in metres) a ray to the tile's centre crosses inside its height slab."""
    c = 0.5 * (lo + hi)
    d = c - view.eye
    horiz = float(np.hypot(d[0], d[1]))
    tan_el = abs(d[2]) / horiz if horiz > 0 else np.inf
    dz = float(hi[2] - lo[2])
    diag = n * np.sqrt(2.0)
    if tan_el == np.inf or dz == 0.0:
        return 0.0 if dz == 0.0 else 1.0
    if tan_el == 0.0:
        return float(diag)
    cells_per_m = float(np.hypot(d[0] / spacing_xy[0], d[1] / spacing_xy[1])) / horiz  # along the ray's heading
    return float(min(dz / tan_el * cells_per_m, diag))


def tile_features(
    pyramid: TilePyramid, view: View, sel: SelectedTile, triangles: float, visible: float = 1.0
) -> TileFeatures:
    """Features of one selected tile; ``triangles`` and their ``visible`` share come from the raster strategy's
    estimate for this view."""
    lo, hi = pyramid.aabb(sel.key)
    k = 1 << sel.key.level
    spacing = (pyramid.hf.spacing_x * k, pyramid.hf.spacing_y * k)
    mid = np.array([lo[0], lo[1], 0.5 * (lo[2] + hi[2])]), np.array([hi[0], hi[1], 0.5 * (lo[2] + hi[2])])
    return TileFeatures(
        footprint_pixels(view, lo, hi),
        float(triangles),
        slab_cells(view, lo, hi, spacing, pyramid.n),
        sel.key.level,
        sel.distance,
        float(visible),
        footprint_pixels(view, *mid),
    )


def slab_cells_batch(view: View, lo: np.ndarray, hi: np.ndarray, spacing: np.ndarray, n: int) -> np.ndarray:
    """``slab_cells`` of B tiles at once: (B, 3) box corners in metres, (B, 2) (x, y) sample spacings in metres.

    dz / tan(elevation) metres along the heading is dz * horizontal / |vertical| metres, so the cells are
    dz * (cells along the heading to the centre) / |vertical|: no angle is formed."""
    from .plan_loops import slab_cells_loop

    f64 = np.float64
    return slab_cells_loop(
        np.ascontiguousarray(lo, dtype=f64).reshape(-1, 3),
        np.ascontiguousarray(hi, dtype=f64).reshape(-1, 3),
        np.ascontiguousarray(spacing, dtype=f64).reshape(-1, 2),
        np.asarray(view.eye, dtype=f64),
        float(n),
    )


def feature_columns(pyramid: TilePyramid, view: View, selected: list[SelectedTile], triangles, visible=None) -> dict:
    """The features of all selected tiles of a frame as arrays, one per ``TileFeatures`` field (B,) each.

    Equal to ``tile_features`` of each tile (within float rounding); ``triangles`` gives each tile's count and
    ``visible`` their share inside the frustum (default 1).
    """
    if isinstance(selected, TileSelection):  # select_tiles' own arrays
        keys, lo, hi, distance = selected.keys, selected.lo, selected.hi, selected.distance
    else:
        keys = np.array([(s.key.level, s.key.tx, s.key.ty) for s in selected], dtype=np.int64).reshape(-1, 3)
        lo, hi = pyramid.aabbs(keys[:, 0], keys[:, 1], keys[:, 2])
        distance = np.array([s.distance for s in selected], dtype=np.float64).reshape(-1)
    from .plan_loops import with_mid_boxes

    lo, hi = np.ascontiguousarray(lo, dtype=np.float64), np.ascontiguousarray(hi, dtype=np.float64)
    b = len(keys)
    area = footprints(view, *with_mid_boxes(lo.reshape(-1, 3), hi.reshape(-1, 3)))
    k = (1 << keys[:, 0]).astype(np.float64)
    spacing = k[:, None] * np.array([pyramid.hf.spacing_x, pyramid.hf.spacing_y])
    return {
        "pixels": area[:b],
        "triangles": np.asarray(triangles, dtype=np.float64).reshape(b),
        "slab_cells": slab_cells_batch(view, lo, hi, spacing, pyramid.n),
        "level": keys[:, 0],
        "distance": distance,
        "visible": np.ones(b) if visible is None else np.asarray(visible, dtype=np.float64).reshape(b),
        "surface_pixels": area[b:],
    }


def features_from_columns(columns: dict) -> list[TileFeatures]:
    """One ``TileFeatures`` per row of ``feature_columns`` (plain Python floats and ints)."""
    names = [f.name for f in fields(TileFeatures)]
    rows = zip(*(columns[n].tolist() for n in names))
    return [TileFeatures(**dict(zip(names, r))) for r in rows]


def tile_features_batch(
    pyramid: TilePyramid, view: View, selected: list[SelectedTile], triangles, visible=None
) -> list[TileFeatures]:
    """``tile_features`` of every selected tile of a frame in one vectorized computation."""
    return features_from_columns(feature_columns(pyramid, view, selected, triangles, visible))
