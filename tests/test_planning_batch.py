"""Batched planning: features, predictions and choices of a whole frame equal the tile-by-tile reference."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hybrid.camera.flight import preset
from hybrid.camera.view import View
from hybrid.cost.features import (
    _convex_hull,
    _hull_area_clipped,
    feature_columns,
    footprint_pixels,
    tile_features,
    tile_features_batch,
)
from hybrid.cost.footprint import clipped_signed_areas, footprints, near_cut
from hybrid.cost.model import load_cost_model
from hybrid.cost.planner import plan_frame
from hybrid.terrain.datasets import cliff, fbm, puget, ridged
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.tiletree import select_tiles

MODEL = load_cost_model("llvmpipe (LLVM 15.0.6, 256 bits)")
# A shoelace sum over pixel coordinates of a few hundred, of polygons with up to a dozen vertices, carries
# about 1e-16 * 640 * 360 * 12 ~ 3e-10 px² of rounding whatever the order of the vertices: the two
# computations of a footprint far below a pixel agree to that absolute amount (seen: 1.5e-9 px² on 0.045 px²),
# not relatively.
RTOL, ATOL = 1e-9, 1e-8


def _views(hf, frames=6):
    views = [v for name in ("flyover", "orbit", "grazing", "lookdown") for v in preset(name, hf, frames).views()]
    # a low eye inside the terrain's boxes, so that near-plane cuts of tile boxes are covered too
    x0, y0, z0 = hf.origin
    w, d = hf.extent
    lo, hi = hf.height_range
    views.append(View([x0 + 0.5 * w, y0 + 0.3 * d, z0 + hi + 5], [x0 + 0.5 * w, y0 + 0.9 * d, z0 + lo], 70, 320, 200))
    return views


@pytest.mark.parametrize(
    "hf,size", [(puget(), 256), (puget(), 64), (fbm(257, seed=3), 32), (ridged(257), 64), (cliff(129), 16)]
)
def test_batch_features_equal_per_tile(hf, size):
    pyramid = TilePyramid(hf, size)
    tiles = cut = 0
    for view in _views(hf):
        sel = select_tiles(pyramid, view, 2 / 3)
        tri = np.arange(len(sel)) * 37.0
        vis = np.linspace(0.0, 1.0, len(sel))
        ref = [tile_features(pyramid, view, s, t, v) for s, t, v in zip(sel, tri, vis)]
        got = tile_features_batch(pyramid, view, sel, tri, vis)
        for a, b in zip(ref, got):
            for name, value in a.as_dict().items():
                assert np.isclose(getattr(b, name), value, rtol=RTOL, atol=ATOL), (name, value, getattr(b, name))
        tiles += len(sel)
        lo, hi = pyramid.aabbs(*np.array([(s.key.level, s.key.tx, s.key.ty) for s in sel]).T)
        cut += int(np.sum(near_cut(view, lo, hi)))
        # the selection's own arrays (which the batch reads) are its tiles', in its order
        assert np.array_equal(sel.keys, [(s.key.level, s.key.tx, s.key.ty) for s in sel])
        assert np.array_equal(sel.lo, lo) and np.array_equal(sel.hi, hi)
        assert np.array_equal(sel.distance, [s.distance for s in sel])
    assert tiles > 50 and cut > 0  # many tiles, and some boxes reach behind the eye


def test_aabbs_equal_per_key():
    pyramid = TilePyramid(fbm(300, seed=1), 32)
    keys = [k for level in range(pyramid.max_level + 1) for k in pyramid.keys(level)]
    lo, hi = pyramid.aabbs(*np.array([(k.level, k.tx, k.ty) for k in keys]).T)
    for k, a, b in zip(keys, lo, hi):
        ra, rb = pyramid.aabb(k)
        assert np.array_equal(a, ra) and np.array_equal(b, rb)


def test_footprints_of_boxes_seen_from_every_side():
    rng = np.random.default_rng(5)
    view = View([0, 0, 0], [0, 100, 0], 70, 300, 200, near=0.5)
    lo = rng.uniform(-60, 60, (400, 3)) + [0, 40, 0]
    hi = lo + rng.uniform(0, 40, (400, 3)) * (rng.random((400, 3)) > 0.1)  # some flat boxes
    area = footprints(view, lo, hi)
    for i in range(len(lo)):
        assert np.isclose(area[i], footprint_pixels(view, lo[i], hi[i]), rtol=RTOL, atol=ATOL)
    corners = np.stack([np.where(np.array([(c >> 2) & 1, (c >> 1) & 1, c & 1], bool), hi, lo) for c in range(8)], 1)
    p = view.project(corners.reshape(-1, 3)).reshape(len(lo), 8, 3)
    ahead = ((corners - view.eye) @ view.forward > view.near).all(axis=1)
    past = ahead & ((p[..., 0] < 0) | (p[..., 0] > 300) | (p[..., 1] < 0) | (p[..., 1] > 200)).any(axis=1)
    assert np.sum(area > 0) > 100 and np.sum(past & (area > 0)) > 20  # many seen, many clipped at the border
    assert np.sum(~ahead & (area > 0)) > 5  # and some cut at the near plane


def test_batch_plans_equal_per_tile_plans():
    hf = puget()
    for size in (256, 128):
        pyramid = TilePyramid(hf, size)
        for view in _views(hf, 4):
            for policy in ("hybrid", "heuristic", "oracle", "raycast"):
                a = plan_frame(pyramid, view, MODEL, policy=policy)
                b = plan_frame(pyramid, view, MODEL, policy=policy, batch=False)
                assert [p.key for p in a] == [p.key for p in b] and [p.choice for p in a] == [p.choice for p in b]
                for x, y in zip(a, b):
                    assert x.predicted.keys() == y.predicted.keys()
                    for s in x.predicted:
                        assert np.isclose(x.predicted[s], y.predicted[s], rtol=RTOL, atol=1e-12)


def test_feature_columns_of_no_tiles():
    pyramid = TilePyramid(fbm(65), 16)
    cols = feature_columns(pyramid, preset("orbit", pyramid.hf, 2).view(0), [], [])
    assert all(len(v) == 0 for v in cols.values())


def test_clipped_areas_equal_the_clipped_hulls():
    """The viewport clip by clamping (hybrid.cost.footprint) against a Sutherland-Hodgman clip of the same convex
    polygons (the scalar reference's), either orientation, polygons inside, across the border, around and off."""
    rng = np.random.default_rng(11)
    w, h = 320.0, 200.0
    polys, want = [], []
    for i in range(300):
        c, r = rng.uniform(-200, 520, 2), rng.uniform(1, 500, 2)
        ang = np.sort(rng.uniform(0, 2 * np.pi, 6))
        p = np.round(c + r * np.stack([np.cos(ang), np.sin(ang)], 1), 6)  # as projected points are
        polys.append(p if i % 2 else p[::-1])  # counter-clockwise and clockwise
        want.append(_hull_area_clipped(p, w, h))
    polys.append(np.array([[-1e3, -1e3], [1e3, -1e3], [1e3, 1e3], [1e3, 1e3], [-1e3, 1e3], [-1e3, 1e3]]))
    want.append(w * h)  # around the viewport, padded by repeats
    got = clipped_signed_areas(np.array(polys), w, h)
    assert np.allclose(np.abs(got), want, rtol=1e-9, atol=1e-8)
    assert np.all(got[:300:2] <= 1e-8) and np.all(got[1:300:2] >= -1e-8)  # each polygon's own orientation
    assert np.sum(np.array(want) == 0) > 10 and np.sum((np.array(want) > 0) & (np.array(want) < w * h)) > 100


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 12), st.booleans())
def test_clipped_areas_of_polygons_on_the_viewport_grid(seed, k, clockwise):
    """The clip's degenerate cases: convex polygons whose vertices lie on a coarse grid that includes the
    viewport's edges, so that edges run along the border, vertical and horizontal edges lie outside it, vertices
    repeat (padding) and polygons collapse to segments or points; against the Sutherland-Hodgman reference."""
    rng = np.random.default_rng(seed)
    w, h = 320.0, 200.0
    grid = np.array([-160.0, 0.0, 80.0, 160.0, 200.0, 320.0, 480.0])
    hull = np.array(_convex_hull(rng.choice(grid, (k, 2)))).reshape(-1, 2)  # x, y on the grid: 0, w, h among them
    poly = hull[::-1] if clockwise else hull
    padded = np.concatenate([poly, np.repeat(poly[-1:], 3, axis=0)])
    want = _hull_area_clipped(poly, w, h) if len(poly) >= 3 else 0.0
    got = clipped_signed_areas(padded[None], w, h)[0]
    assert np.isclose(abs(got), want, rtol=1e-9, atol=1e-8), (poly, got, want)
    assert (got <= 1e-8) if clockwise else (got >= -1e-8)


def test_slab_cells_batch_equals_the_scalar_at_its_edge_cases():
    """Eye straight above a box's centre, level with it, both, flat boxes and general ones: the batch's closed form
    against the scalar angle-based reference."""
    from hybrid.cost.features import slab_cells, slab_cells_batch

    view = View([50.0, 50.0, 10.0], [0.0, 0.0, 0.0])
    rng = np.random.default_rng(2)
    lo = np.array(
        [[40, 40, 0], [40, 40, 5], [0, 0, 0], [0, 0, 3], [40, 40, 10]] + rng.uniform(-80, 80, (40, 3)).tolist()
    )
    hi = lo + np.array(
        [[20, 20, 4], [20, 20, 10], [30, 20, 20], [30, 20, 0], [20, 20, 0]] + rng.uniform(0, 30, (40, 3)).tolist()
    )
    spacing = np.tile([2.0, 3.0], (len(lo), 1))
    want = [slab_cells(view, a, b, s, 64) for a, b, s in zip(lo, hi, spacing)]
    got = slab_cells_batch(view, lo, hi, spacing, 64)
    assert np.allclose(got, want, rtol=1e-12, atol=0)
    assert got[0] == 1.0 and got[1] == 1.0 and got[3] == 0.0 and got[4] == 0.0  # above (and level): 1; flat: 0
    assert got[2] == 64 * np.sqrt(2.0) and np.isfinite(got).all()  # level with the eye: the diagonal
