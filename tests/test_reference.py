"""The reference image against an exact CPU ray/triangle intersection, and the far-from-origin case."""

import numpy as np
import pytest
from spacing_helpers import NON_SQUARE, terrain

from hybrid.camera.view import View, default_view
from hybrid.errors import TerrabenchError
from hybrid.reference import ReferenceRenderer, grid_indices

SIZE = (320, 180)


def cpu_hits(hf, origins, dirs):
    """Nearest hit distance of each ray with the full triangulated surface (brute force, float64)."""
    i, j = np.mgrid[0 : hf.rows, 0 : hf.cols]
    verts = np.stack(
        [
            hf.origin[0] + j * hf.spacing_x,
            hf.origin[1] + i * hf.spacing_y,
            hf.origin[2] + hf.heights.astype(np.float64),
        ],
        -1,
    ).reshape(-1, 3)
    tri = grid_indices(hf.rows, hf.cols).reshape(-1, 3).astype(np.int64)
    v0, v1, v2 = verts[tri[:, 0]], verts[tri[:, 1]], verts[tri[:, 2]]
    e1, e2 = v1 - v0, v2 - v0
    out = np.full(len(dirs), np.inf)
    for r, (o, d) in enumerate(zip(origins, dirs)):  # Moller-Trumbore over all triangles, one ray at a time
        p = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, p)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = o - v0
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = (q @ d) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        if hit.any():
            out[r] = t[hit].min()
    return out


def _views(hf):
    w, d = hf.extent
    ox, oy, _ = hf.origin
    yield default_view(hf, *SIZE)
    x, y = ox + 0.3 * w, oy + 0.2 * d
    z = float(hf.ground_height(x, y)) + 150.0
    yield View([x, y, z], [ox + w, oy + d, z - 600.0], 60.0, *SIZE, near=1.0, far=1e6)


@pytest.mark.parametrize("spacing", [None, *NON_SQUARE])
def test_reference_matches_cpu_intersection(ctx, puget257, spacing):
    """Puget Sound (160 m square cells) and a synthetic terrain with non-square cells (x, y metres)."""
    hf = puget257 if spacing is None else terrain(spacing)
    ref = ReferenceRenderer(ctx, hf)
    rng = np.random.default_rng(7)
    for view in _views(hf):
        res = ref.render(view, mode="shaded")
        rows = rng.integers(0, view.height, 150)
        cols = rng.integers(0, view.width, 150)
        dirs = view.pixel_rays(rows, cols)
        want = cpu_hits(hf, np.repeat(view.eye[None], len(dirs), 0), dirs)
        got = res.distance[rows, cols].astype(np.float64)
        hit_w, hit_g = np.isfinite(want), np.isfinite(got)
        # a pixel centre within a hair of a silhouette may flip; demand near-total agreement
        assert (hit_w == hit_g).mean() >= 0.98
        assert hit_w.sum() > 40
        both = hit_w & hit_g
        rel = np.abs(got[both] - want[both]) / want[both]
        assert np.median(rel) < 1e-5 and np.percentile(rel, 95) < 1e-3
    ref.release()


def test_far_from_origin_renders_the_same(ctx, puget257):
    view = list(_views(puget257))[1]
    offset = np.array([5.0e6, 5.0e6, 0.0])  # 5,000 km east and north
    a = ReferenceRenderer(ctx, puget257)
    b = ReferenceRenderer(ctx, puget257.moved(np.array(puget257.origin) + offset))
    ra, rb = a.render(view), b.render(view.moved(offset))
    assert (ra.mask == rb.mask).mean() > 0.999
    m = ra.mask & rb.mask
    rel = np.abs(ra.distance[m] - rb.distance[m]) / ra.distance[m]
    assert np.median(rel) < 1e-5 and rel.max() < 1e-3
    assert np.abs(ra.colour.astype(int) - rb.colour.astype(int)).mean() < 1.0
    a.release()
    b.release()


def test_supersampling_and_outputs(ctx, puget257, tmp_path):
    ref = ReferenceRenderer(ctx, puget257)
    view = default_view(puget257, 160, 90)
    r1 = ref.render(view)
    r3 = ref.render(view, supersample=3)
    assert np.array_equal(r1.distance, r3.distance)  # depth and coverage at pixel centres
    assert r1.colour.shape == r3.colour.shape == (90, 160, 3)
    assert 0 < np.abs(r1.colour.astype(int) - r3.colour.astype(int)).mean() < 30
    assert np.all(np.isinf(r1.distance[~r1.mask])) and np.all(r1.distance[r1.mask] > 0)
    png, depth = r1.save(tmp_path / "a.png")
    assert png.exists() and np.array_equal(np.load(depth), r1.distance)
    with pytest.raises(TerrabenchError, match="supersample"):
        ref.render(view, supersample=0)
    with pytest.raises(TerrabenchError, match="shading mode"):
        ref.render(view, mode="glow")
    ref.release()
