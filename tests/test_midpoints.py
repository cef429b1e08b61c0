"""Lean full-resolution leaves: the error of a dropped midpoint (raster.midpoints) against the surfaces drawn.

The drawn leaf is triangulated here as the geometry shader and the indexed path draw a level-0 leaf
(raster/tilelet.geom.glsl, put_mesh in raster/select.comp.glsl), the reference as SW-NE cells, and both are
sampled on a fine grid: the largest height difference must be the largest error of the dropped midpoints.
"""
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from raster.midpoints import midpoint_errors
from raster.quadtree import error_pyramid
from raster.restriction import EDGE_BITS, TileLod, restrict_frame

C, SW, S, SE, E, NE, N, NW, W = (1, 1), (0, 0), (0, 1), (0, 2), (1, 2), (2, 2), (2, 1), (2, 0), (1, 0)


def leaf_triangles(drop: int) -> list:
    """A level-0 leaf's triangles (posts as (row, column) in 0..2) with edge bits W=1, E=2, S=4, N=8 dropped."""
    se, nw = (drop & 6) == 0, (drop & 9) == 0
    t = []
    t += [(C, SW, SE)] if drop & 4 else [(C, SW, S)] + ([] if se else [(C, S, SE)])
    t += [(C, SE, NE)] if drop & 2 else ([] if se else [(C, SE, E)]) + [(C, E, NE)]
    t += [(C, NE, NW)] if drop & 8 else [(C, NE, N)] + ([] if nw else [(C, N, NW)])
    t += [(C, NW, SW)] if drop & 1 else ([] if nw else [(C, NW, W)]) + [(C, W, SW)]
    if se:
        t += [(S, SE, E), (S, E, C)]
    if nw:
        t += [(W, C, N), (W, N, NW)]
    return t


def sample(h: np.ndarray, triangles: list, pts: np.ndarray) -> np.ndarray:
    """Heights at points (k, 2) of (row, column) of the surface of triangles of sample positions (linear in each)."""
    out = np.full(len(pts), np.nan)
    for a, b, c in triangles:
        A, B, Cc = (np.asarray(p, float) for p in (a, b, c))
        m = np.column_stack([B - A, Cc - A])
        uv = np.linalg.solve(m, (pts - A).T).T
        w = np.column_stack([1 - uv.sum(axis=1), uv])
        inside = np.isnan(out) & (w >= -1e-9).all(axis=1)
        out[inside] = w[inside] @ np.array([h[a], h[b], h[c]])
    return out


def drawn_and_reference(h: np.ndarray, drops: dict) -> tuple[np.ndarray, np.ndarray]:
    """(drawn, reference) heights on a grid of tenth cells over a (2U+1)² patch of level-0 leaves {(a, b): bits}."""
    n = h.shape[0] - 1
    g = np.linspace(0, n, 10 * n + 1)
    pts = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    drawn, ref = np.full(len(pts), np.nan), np.full(len(pts), np.nan)
    for (a, b), bits in drops.items():
        off = np.array([2 * a, 2 * b])
        inside = np.all((pts >= off - 1e-9) & (pts <= off + 2 + 1e-9), axis=1) & np.isnan(drawn)
        drawn[inside] = sample(h[2 * a:2 * a + 3, 2 * b:2 * b + 3], leaf_triangles(bits), pts[inside] - off)
    for r in range(n):
        for c in range(n):
            inside = np.all((pts >= (r - 1e-9, c - 1e-9)) & (pts <= (r + 1 + 1e-9, c + 1 + 1e-9)), axis=1) & np.isnan(ref)
            ref[inside] = sample(h[r:r + 2, c:c + 2], [((0, 0), (0, 1), (1, 1)), ((0, 0), (1, 1), (1, 0))],
                                 pts[inside] - (r, c))
    return drawn, ref


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(0, 2**12 - 1))
def test_a_dropped_midpoints_error_is_the_largest_height_difference_it_makes(seed, chosen):
    """Over a 2 x 2 patch of level-0 leaves with any set of its 12 edges' midpoints dropped (shared edges on both
    sides), the drawn surface differs from the reference's cells by at most, and somewhere by exactly, the
    largest of the dropped midpoints' errors: not only at the samples, but inside the cells."""
    rng = np.random.default_rng(seed)
    h = rng.normal(0.0, 10.0, (5, 5))
    ex, ey = midpoint_errors(h)
    # the patch's edges: vertical ones ex[a, c] (W side of unit (a, c)), horizontal ones ey[r, b] (S side of (r, b))
    edges = [("x", a, c) for a in range(2) for c in range(3)] + [("y", r, b) for r in range(3) for b in range(2)]
    drops = {(a, b): 0 for a in range(2) for b in range(2)}
    worst = 0.0
    for i, (kind, p, q) in enumerate(edges):
        if not (chosen >> i) & 1:
            continue
        if kind == "x":                                  # units (p, q - 1) east, (p, q) west
            worst = max(worst, ex[p, q])
            if q > 0:
                drops[(p, q - 1)] |= EDGE_BITS[1]
            if q < 2:
                drops[(p, q)] |= EDGE_BITS[0]
        else:                                            # units (p - 1, q) north, (p, q) south
            worst = max(worst, ey[p, q])
            if p > 0:
                drops[(p - 1, q)] |= EDGE_BITS[3]
            if p < 2:
                drops[(p, q)] |= EDGE_BITS[2]
    drawn, ref = drawn_and_reference(h, drops)
    diff = np.abs(drawn - ref).max()
    assert not np.isnan(drawn).any() and not np.isnan(ref).any()
    assert np.isclose(diff, worst, rtol=1e-9, atol=1e-9), (diff, worst)


def test_full_resolution_leaves_drop_the_midpoints_the_bound_allows():
    """Without morphing, restrict_frame's lean full-resolution leaves drop exactly the midpoints whose error is
    within the tolerance on edges shared with a level-0 leaf (both sides alike) or on the terrain's edge (a
    lone tile: its borders), besides those toward coarser leaves; none at zero tolerance on a surface with no
    flat part."""
    rng = np.random.default_rng(3)
    h = np.cumsum(np.cumsum(rng.normal(0.0, 1.0, (17, 17)), axis=0), axis=1)
    pyr = error_pyramid(h, 0.9)
    ex, ey = midpoint_errors(h)
    counts = []
    for tol in (0.0, 0.5, 2.0, 8.0):
        ts = restrict_frame([TileLod((0, 0, 0), pyr, tol)], morph=False, use_effective=False, lean=True)[(0, 0, 0)]
        lv, drop = ts.leaves, ts.drop
        zero = lv.level == 0
        a, b = lv.i0[zero] // 2, lv.j0[zero] // 2
        d = drop[zero]
        level = ts.level_map
        for bit, err, na, nb in ((1, ex[a, b], a, b - 1), (2, ex[a, b + 1], a, b + 1),
                                 (4, ey[a, b], a - 1, b), (8, ey[a + 1, b], a + 1, b)):
            inside = (na >= 0) & (na < 8) & (nb >= 0) & (nb < 8)
            beside = np.zeros(len(a), bool)
            beside[inside] = level[na[inside], nb[inside]] == 0
            terrain_edge = ~inside
            expect = (beside | terrain_edge) & (err <= tol)
            coarser = (ts.coarser[zero] & bit) != 0
            assert np.array_equal(((d & bit) != 0) & ~coarser, expect & ~coarser), (tol, bit)
        counts.append(int(np.unpackbits(d.astype(np.uint8)[:, None], axis=1).sum()))
    assert counts[0] == 0 and min(counts[1:]) > 20, counts
