"""Golden arrays: the error pyramid, the leaf set and CPU ray hits of tiny fixed grids, compared with files
made by tests/golden/make_golden.py, and every stored value checked on its own terms as well."""

from pathlib import Path

import numpy as np

from raster.quadtree import Leaves, drawn_max_error, error_pyramid, leaf_levels, leaves_from_levels
from raycast.cpu import HIT, MISS, cast_rays

GOLDEN = Path(__file__).parent / "golden"
F32 = np.finfo(np.float32).eps


def load(name: str) -> dict:
    with np.load(GOLDEN / f"{name}.npz") as d:
        return dict(d)


def assert_close(got, want):
    """Equal within float32 eps (NaN where the golden value is NaN)."""
    got, want = np.asarray(got, np.float64), np.asarray(want, np.float64)
    assert got.shape == want.shape
    assert np.array_equal(np.isnan(got), np.isnan(want))
    ok = ~np.isnan(want)
    assert np.allclose(got[ok], want[ok], rtol=F32, atol=F32), np.abs(got[ok] - want[ok]).max()


def test_error_pyramid_golden():
    g = load("error_pyramid")
    h = g["heights"].astype(np.float64)
    p = error_pyramid(g["heights"])
    assert p.top == 2
    for m in range(p.top + 1):
        assert_close(p.errors[m], g[f"errors{m}"])
        assert_close(p.effective[m], g[f"effective{m}"])
        assert_close(p.sides[m], g[f"sides{m}"])
    # Level 0: the full fan's posts are all nine samples, so it has no error; a side's error is where the
    # stitched fan drops that edge's midpoint, |midpoint - mean of the edge's corners|, or where the fan edge
    # from the centre post to the SE (NW) corner crosses that cell's SW-NE diagonal, |mean(centre, corner) -
    # mean of the diagonal's ends|, and that with the midpoints on their edges, |centre - mean(SW, NE)| / 2, for
    # sides S and E (W and N). Node (0, 0) by hand: samples (south row first) 9 10 15 / 6 18 8 / 1 0 18 give
    # W max(|6 - 5|, |9.5 - 3|, 2.25) = 6.5, E max(|8 - 16.5|, |16.5 - 9|) = 8.5, S max(|10 - 12|, 7.5) = 7.5,
    # N max(|0 - 9.5|, 6.5) = 9.5.
    assert not g["errors0"].any()
    assert list(g["sides0"][:, 0, 0]) == [6.5, 8.5, 7.5, 9.5]
    want = np.zeros((4, 4, 4))
    for a in range(4):
        for b in range(4):
            s = h[2 * a : 2 * a + 3, 2 * b : 2 * b + 3]
            flip = abs(s[1, 1] - (s[0, 0] + s[2, 2]) / 2) / 2
            se = max(abs((s[1, 1] + s[0, 2]) / 2 - (s[0, 1] + s[1, 2]) / 2), flip)
            nw = max(abs((s[1, 1] + s[2, 0]) / 2 - (s[1, 0] + s[2, 1]) / 2), flip)
            want[:, a, b] = (
                max(abs(s[1, 0] - (s[0, 0] + s[2, 0]) / 2), nw),
                max(abs(s[1, 2] - (s[0, 2] + s[2, 2]) / 2), se),
                max(abs(s[0, 1] - (s[0, 0] + s[0, 2]) / 2), se),
                max(abs(s[2, 1] - (s[2, 0] + s[2, 2]) / 2), nw),
            )
    assert np.array_equal(g["sides0"], want)
    # a parent's error is at least its children's and the side errors facing it from outside (the W
    # neighbour's E side, ...); the effective error at least the error
    for m in range(1, p.top + 1):
        kids = g[f"errors{m - 1}"].reshape(g[f"errors{m}"].shape[0], 2, -1, 2).max(axis=(1, 3))
        assert np.all(g[f"errors{m}"] >= kids) and np.all(g[f"effective{m}"] >= g[f"errors{m}"])
    W, E = g["sides0"][0], g["sides0"][1]
    assert g["errors1"][0, 1] >= max(E[0, 1], E[1, 1])  # node (0, 1)'s W edge faces level-0 nodes (0..1, 1)
    assert g["errors1"][0, 0] >= max(W[0, 2], W[1, 2])


def test_leaf_set_golden():
    g = load("leaves")
    h, tol = g["heights"], float(g["tolerance"])
    lv = leaves_from_levels(leaf_levels(error_pyramid(h), tol))
    for k in ("i0", "j0", "level"):
        assert np.array_equal(getattr(lv, k), g[k]), k
    n = h.shape[0] - 1
    # the golden leaves cover every cell of the tile exactly once, at levels 0..2 (2^(level+1) cells a side)
    cover = np.zeros((n, n), np.int64)
    level_of = np.full((n, n), -1)
    for i0, j0, m in zip(g["i0"], g["j0"], g["level"]):
        s = 2 << int(m)
        cover[i0 : i0 + s, j0 : j0 + s] += 1
        level_of[i0 : i0 + s, j0 : j0 + s] = m
    assert np.all(cover == 1)
    assert set(np.unique(g["level"])) == {0, 1, 2}
    # restricted: edge-adjacent cells' leaves differ by at most one level
    assert np.abs(np.diff(level_of, axis=0)).max() <= 1 and np.abs(np.diff(level_of, axis=1)).max() <= 1
    # each leaf's drawn fan lies within the tolerance of the samples it covers
    leaves = Leaves(g["i0"], g["j0"], g["level"])
    assert drawn_max_error(h, leaves).max() <= tol
    # the plane away from the bump (north-east quarter) is drawn with the coarsest leaves of the set
    ne = (g["i0"] >= n // 2) & (g["j0"] >= n // 2)
    assert ne.any() and np.all(g["level"][ne] == g["level"].max())


def triangle_height(h: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Height of the grid's triangulated surface at texel (x, y): each cell split along its SW-NE diagonal."""
    n = h.shape[0] - 1
    j = np.clip(np.floor(x).astype(int), 0, n - 1)
    i = np.clip(np.floor(y).astype(int), 0, n - 1)
    fx, fy = x - j, y - i
    h00, h01, h10, h11 = h[i, j], h[i, j + 1], h[i + 1, j], h[i + 1, j + 1]
    return np.where(fx >= fy, h00 + fx * (h01 - h00) + fy * (h11 - h01), h00 + fy * (h10 - h00) + fx * (h11 - h10))


def test_cpu_ray_hits_golden():
    g = load("rays")
    h = g["heights"].astype(np.float64)
    n = h.shape[0] - 1
    O, D = g["origin"], g["direction"]
    r = cast_rays(g["heights"], (float(n), float(n)), (h.min(), h.max()), O, D, reconstruction="triangles")
    assert np.array_equal(r.status, g["status"])
    assert_close(r.point, g["point"])
    status, point = g["status"], g["point"]
    assert status[-1] == MISS  # points up from above the highest sample
    assert status[6] == HIT and point[6, 0] == O[6, 0] and point[6, 1] == O[6, 1]  # straight down
    assert (status == HIT).sum() >= 7
    hit = status == HIT
    # a hit lies on the surface and on its ray, ahead of the origin
    assert np.abs(point[hit, 2] - triangle_height(h, point[hit, 0], point[hit, 1])).max() <= 1e-6
    t = np.einsum("ij,ij->i", point[hit] - O[hit], D[hit]) / np.einsum("ij,ij->i", D[hit], D[hit])
    assert np.all(t > 0)
    assert np.abs(O[hit] + t[:, None] * D[hit] - point[hit]).max() <= 1e-9
    # and it is the first: the ray is above the surface wherever it crosses the grid before the hit; a
    # miss is above it all the way across
    t_end = np.where(hit, 0.0, 100.0)
    t_end[hit] = t
    for o, d, te in zip(O, D, t_end):
        s = np.linspace(0.0, te, 4001)[:-1]
        p = o + s[:, None] * d
        inside = (p[:, 0] >= 0) & (p[:, 0] <= n) & (p[:, 1] >= 0) & (p[:, 1] <= n)
        assert np.all(p[inside, 2] >= triangle_height(h, p[inside, 0], p[inside, 1]) - 1e-9)
