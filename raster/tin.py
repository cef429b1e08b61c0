"""Decimated-TIN baseline: each tile's full-resolution grid simplified by fast-simplification (quadric edge
collapse) to a target triangle count or a max vertical error, with trimesh as the mesh container.

Tiles are simplified independently and drawn each at its own level, unstitched by design, so their border
vertices do not match: the TINs part at tile borders. ``border_gaps`` measures that; the strategy hangs skirts
from the sides that face a neighbour, as deep as the two surfaces differ along them (raster.mesh_skirts), so no
background shows through; ``preserve_border=True`` keeps the border vertices (no gaps between same-level
tiles, more triangles). Otherwise border vertices are held to the tile's outline: a vertical wall hangs from
each side during the simplification, so its plane enters the border vertices' quadrics (Garland and Heckbert's
boundary constraint planes), and is cut off afterwards. Without it a collapse on flat ground costs nothing, and
a flat region (a sea) at a tile's border is pulled in until most of it is gone. The walls keep most border
vertices on the outline, not all: some stray a few cells inside, near corners most, leaving a sliver of the
tile uncovered (``tin_max_error`` counts its samples), which the skirts' flange covers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import spacing_pair

from .meshes import MeshStrategyBase
from .trianglelist import grid_faces, grid_vertices


@dataclass(frozen=True)
class TinMesh:
    """A TIN: vertices (v, 3) float64 metres (tile-local x, y; z height), faces (f, 3) int64, CCW from above."""

    vertices: np.ndarray
    faces: np.ndarray

    @property
    def triangles(self) -> int:
        """Number of triangles."""
        return int(len(self.faces))


def surface_at(vertices: np.ndarray, faces: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Heights (metres) of a TIN at grid points (x, y) (metres) and how many triangles cover each point.

    Where triangles overlap (fold-overs) one covering triangle's height is returned; uncovered points get NaN.
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    out = np.full(x.size, np.nan)
    hits = np.zeros(x.size, np.int32)
    if F.size == 0:
        return out, hits
    # points are on a regular grid: index them by (row, col) and enumerate each triangle's bounding box
    xs, ys = np.unique(x), np.unique(y)
    dx = xs[1] - xs[0] if xs.size > 1 else 1.0
    dy = ys[1] - ys[0] if ys.size > 1 else 1.0
    col_of = np.rint((x - xs[0]) / dx).astype(np.int64)
    row_of = np.rint((y - ys[0]) / dy).astype(np.int64)
    grid = np.full((ys.size, xs.size), -1, np.int64)
    grid[row_of, col_of] = np.arange(x.size)
    P = V[F]  # (f, 3, 3)
    c0 = np.clip(np.floor((P[:, :, 0].min(1) - xs[0]) / dx - 1e-9).astype(np.int64), 0, xs.size - 1)
    c1 = np.clip(np.ceil((P[:, :, 0].max(1) - xs[0]) / dx + 1e-9).astype(np.int64), 0, xs.size - 1)
    r0 = np.clip(np.floor((P[:, :, 1].min(1) - ys[0]) / dy - 1e-9).astype(np.int64), 0, ys.size - 1)
    r1 = np.clip(np.ceil((P[:, :, 1].max(1) - ys[0]) / dy + 1e-9).astype(np.int64), 0, ys.size - 1)
    w, h = c1 - c0 + 1, r1 - r0 + 1
    counts = w * h
    tri = np.repeat(np.arange(len(F)), counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    rr = r0[tri] + local // w[tri]
    cc = c0[tri] + local % w[tri]
    pt = grid[rr, cc]
    ok = pt >= 0
    tri, pt = tri[ok], pt[ok]
    a, b, c = P[tri, 0], P[tri, 1], P[tri, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    good = np.abs(det) > 1e-12
    tri, pt, a, b, c, det = tri[good], pt[good], a[good], b[good], c[good], det[good]
    px, py = x[pt], y[pt]
    l1 = ((px - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (py - a[:, 1])) / det
    l2 = ((b[:, 0] - a[:, 0]) * (py - a[:, 1]) - (px - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
    l0 = 1.0 - l1 - l2
    eps = 1e-9
    inside = (l0 >= -eps) & (l1 >= -eps) & (l2 >= -eps)
    z = l0 * a[:, 2] + l1 * b[:, 2] + l2 * c[:, 2]
    out[pt[inside]] = z[inside]
    np.add.at(hits, pt[inside], 1)
    return out, hits


def tin_max_error(mesh: TinMesh, heights: np.ndarray, spacing) -> tuple[float, int]:
    """(largest vertical distance in metres over covered grid samples, number of samples the TIN leaves uncovered);
    spacing in metres, one number or an (x, y) pair."""
    h = np.asarray(heights, dtype=np.float64)
    sx, sy = spacing_pair(spacing, "TIN grid")
    i, j = np.mgrid[0 : h.shape[0], 0 : h.shape[1]]
    z, hits = surface_at(mesh.vertices, mesh.faces, j.ravel() * sx, i.ravel() * sy)
    cov = hits > 0
    return float(np.abs(z[cov] - h.ravel()[cov]).max(initial=0.0)), int(np.count_nonzero(~cov))


def _walled(pts: np.ndarray, faces: np.ndarray, rows: int, cols: int, depth: float) -> tuple[np.ndarray, np.ndarray]:
    """The grid mesh with a vertical wall ``depth`` metres deep hanging outward-facing from each side of its
    outline; the walls' lower vertices follow the grid's vertices."""
    idx = np.arange(rows * cols).reshape(rows, cols)
    sides = (idx[0], idx[:, -1], idx[-1, ::-1], idx[::-1, 0])  # counter-clockwise around the tile from above
    out_pts, out_faces, base = [pts], [faces], len(pts)
    for top in sides:
        bot = base + np.arange(len(top))
        base += len(top)
        out_pts.append(pts[top] - np.array([0.0, 0.0, depth]))
        out_faces += [np.stack([top[:-1], bot[:-1], bot[1:]], 1), np.stack([top[:-1], bot[1:], top[1:]], 1)]
    return np.concatenate(out_pts), np.concatenate(out_faces).astype(faces.dtype)


def _unwalled(v: np.ndarray, f: np.ndarray, floor: float) -> TinMesh:
    """The simplified mesh without its walls: faces touching a vertex below ``floor`` (metres) removed, the
    vertices still used renumbered."""
    f = np.asarray(f, dtype=np.int64)
    f = f[(v[f, 2] >= floor).all(axis=1)]
    used, f = np.unique(f, return_inverse=True)
    return TinMesh(np.asarray(v, dtype=np.float64)[used], f.reshape(-1, 3))


def build_tin(
    heights: np.ndarray,
    spacing,
    target_count: int | None = None,
    max_error: float | None = None,
    preserve_border: bool = False,
    agg: float = 7.0,
) -> TinMesh:
    """TIN of a tile's heights: simplify the full grid to about ``target_count`` triangles or to <= ``max_error``
    metres; spacing in metres, one number or an (x, y) pair.

    Border vertices are held to the tile's outline (module docstring); with preserve_border they all stay. With
    max_error the reduction is bisected (8 steps) on the measured max vertical error over the samples the TIN
    covers (samples it leaves uncovered are cracks; ``tin_max_error`` counts them).
    """
    import fast_simplification

    h = np.asarray(heights)
    if h.ndim != 2 or min(h.shape) < 2:
        raise TerrabenchError(f"heights must be a 2-D grid of at least 2x2 samples, got shape {h.shape}")
    if (target_count is None) == (max_error is None):
        raise TerrabenchError("give exactly one of target_count (triangles) and max_error (metres)")
    pts = grid_vertices(h, spacing).astype(np.float64)
    faces = grid_faces(h.shape[0], h.shape[1]).astype(np.int32)
    full = len(faces)
    lo_z = float(np.min(h))
    depth = (
        10.0 * (float(np.ptp(h)) + max(spacing_pair(spacing, "TIN grid"))) + 1.0
    )  # far below anything a collapse can reach
    grid = (pts, faces) if preserve_border else _walled(pts, faces, h.shape[0], h.shape[1], depth)
    walls = len(grid[1]) - full

    def simplify(**target) -> TinMesh:
        v, f = fast_simplification.simplify(*grid, agg=agg, preserve_border=preserve_border, **target)
        return _unwalled(v, f, lo_z - 0.5 * depth)

    if target_count is not None:
        if (
            isinstance(target_count, bool)
            or not isinstance(target_count, (int, np.integer))
            or not (2 <= target_count <= full)
        ):
            raise TerrabenchError(f"target_count must be an integer in [2, {full}] triangles, got {target_count!r}")
        if not walls:
            return simplify(target_count=int(target_count))
        # the walls are simplified too: a first pass measures how many of their triangles remain
        m = simplify(target_count=int(target_count) + walls)
        kept_walls = int(target_count) + walls - m.triangles
        return simplify(target_count=min(int(target_count) + max(kept_walls, 0), full + walls))
    assert max_error is not None  # exactly one of target_count and max_error, and not target_count
    if not (np.isfinite(max_error) and max_error >= 0):
        raise TerrabenchError(f"max_error must be finite and >= 0 metres, got {max_error!r}")
    return _bisect_reduction(
        simplify,
        TinMesh(pts, faces.astype(np.int64)),
        1.0 - 2.0 / (full + walls),
        lambda m: tin_max_error(m, h, spacing)[0] <= max_error,
    )


def _bisect_reduction(simplify, full: TinMesh, most: float, good) -> TinMesh:
    """The most reduced TIN ``simplify(target_reduction=r)`` for r in [0, most] that is ``good``, bisected in 8
    steps (the full mesh if none is)."""
    best, lo, hi = full, 0.0, most
    for _ in range(8):
        mid = 0.5 * (lo + hi)
        m = simplify(target_reduction=mid)
        if good(m):
            best, lo = m, mid
        else:
            hi = mid
    return best


def to_trimesh(mesh: TinMesh, origin=(0.0, 0.0, 0.0)):
    """The TIN as a trimesh.Trimesh placed at a world origin (metres)."""
    import trimesh

    return trimesh.Trimesh(
        vertices=mesh.vertices + np.asarray(origin, dtype=np.float64), faces=mesh.faces, process=False
    )


def export_tin(mesh: TinMesh, path, origin=(0.0, 0.0, 0.0)) -> None:
    """Write the TIN as OBJ or PLY (by the path's suffix), vertices in world metres."""
    from pathlib import Path

    p = Path(path)
    if p.suffix.lower() not in (".obj", ".ply"):
        raise TerrabenchError(f"TIN export path must end in .obj or .ply, got {str(path)!r}")
    to_trimesh(mesh, origin).export(p)


def border_gaps(meshes: dict, n: int) -> dict:
    """Vertical mismatch (metres) along shared borders of same-level tiles: {(key_a, key_b): max gap}.

    meshes: {(level, tx, ty): (TinMesh, spacing)}, spacing one number or an (x, y) pair of metres. Samples each
    border at every tile sample position.
    """
    out = {}
    for (l, tx, ty), (ma, sp) in meshes.items():
        sx, sy = spacing_pair(sp, "TIN tile")
        for dx, dy in ((1, 0), (0, 1)):
            kb = (l, tx + dx, ty + dy)
            if kb not in meshes:
                continue
            mb, _ = meshes[kb]
            if dx:
                t = np.arange(n + 1) * sy
                za, _ = surface_at(ma.vertices, ma.faces, np.full(n + 1, n * sx), t)
                zb, _ = surface_at(mb.vertices, mb.faces, np.zeros(n + 1), t)
            else:
                t = np.arange(n + 1) * sx
                za, _ = surface_at(ma.vertices, ma.faces, t, np.full(n + 1, n * sy))
                zb, _ = surface_at(mb.vertices, mb.faces, t, np.zeros(n + 1))
            gap = np.abs(za - zb)
            out[((l, tx, ty), kb)] = float(np.nanmax(gap)) if np.any(np.isfinite(gap)) else float("nan")
    return out


class TinStrategy(MeshStrategyBase):
    """Draws each tile as a decimated TIN (built at upload): ``reduction`` of the triangles removed, or to
    ``max_error`` metres when given."""

    def __init__(self, ctx, hf, reduction: float = 0.9, max_error: float | None = None, preserve_border: bool = False):
        if not (0.0 <= reduction < 1.0):
            raise TerrabenchError(f"reduction must lie in [0, 1), got {reduction!r}")
        super().__init__(ctx, hf)
        self.reduction, self.max_error, self.preserve_border = float(reduction), max_error, bool(preserve_border)
        # (level, tx, ty) -> (the tile's TIN, its spacing)
        self.meshes: dict[tuple[int, int, int], tuple[TinMesh, tuple[float, float]]] = {}

    def mesh_of(self, tile):
        """The tile's TIN (also kept in ``self.meshes`` by key for export and crack measurement)."""
        h = np.asarray(tile.heights)
        full = 2 * (h.shape[0] - 1) * (h.shape[1] - 1)
        if self.max_error is not None:
            m = build_tin(h, tile.spacing_xy, max_error=self.max_error, preserve_border=self.preserve_border)
        else:
            m = build_tin(
                h,
                tile.spacing_xy,
                target_count=max(2, int(round(full * (1 - self.reduction)))),
                preserve_border=self.preserve_border,
            )
        self.meshes[(int(tile.key.level), int(tile.key.tx), int(tile.key.ty))] = (m, tile.spacing_xy)
        return m.vertices, m.faces
