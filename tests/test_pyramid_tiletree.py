"""The tile pyramid (errors, AABBs, padding) and per-view selection (culling, restriction, order)."""

import itertools

import numpy as np
import pytest

from hybrid.camera.view import View, default_view
from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import HeightField
from hybrid.tiles.pyramid import EDGE_E, EDGE_N, EDGE_S, EDGE_W, TileKey, TilePyramid
from hybrid.tiles.tiletree import select_tiles


@pytest.fixture(scope="module")
def pyr(puget_full):
    return TilePyramid(puget_full, 64)


def test_error_grows_with_level(pyr):
    assert all(pyr.error(k) == 0 for k in pyr.keys(0))
    for level in range(1, pyr.max_level + 1):
        for k in pyr.keys(level):
            kids = [c for c in k.children() if pyr.exists(c)]
            assert pyr.error(k) >= max(pyr.error(c) for c in kids)
    means = [np.mean([pyr.error(k) for k in pyr.keys(l)]) for l in range(1, pyr.max_level + 1)]
    assert all(b > a for a, b in itertools.pairwise(means))


def test_error_is_exact_deviation(puget_full, pyr):
    # brute-force the level-1 tile (1, 2, 3): triangulated coarse surface vs every level-0 sample in it
    k = TileKey(1, 2, 3)
    t = pyr.tile(k)
    coarse = HeightField(t.heights, t.spacing_xy)
    n0 = 128
    i, j = np.mgrid[0 : n0 + 1, 0 : n0 + 1]
    fine = puget_full.heights[3 * n0 : 4 * n0 + 1, 2 * n0 : 3 * n0 + 1]
    dev = np.abs(coarse.sample_triangles(i / 2, j / 2) - fine).max()
    kids_max = max(pyr.error(c) for c in k.children())
    assert np.isclose(pyr.error(k), max(dev, kids_max), rtol=1e-6)


def test_aabb_bounds_samples(puget_full, pyr):
    for k in pyr.keys(1):
        lo, hi = pyr.aabb(k)
        j0 = int(round((lo[0] - puget_full.origin[0]) / 160))
        j1 = int(round((hi[0] - puget_full.origin[0]) / 160))
        i0 = int(round((lo[1] - puget_full.origin[1]) / 160))
        i1 = int(round((hi[1] - puget_full.origin[1]) / 160))
        block = puget_full.heights[i0 : i1 + 1, j0 : j1 + 1]
        assert lo[2] == block.min() and hi[2] == block.max()


def test_any_size_is_padded_not_drawn():
    hf = HeightField(np.random.default_rng(0).uniform(0, 50, (300, 500)).astype(np.float32), 10.0)
    p = TilePyramid(hf, 64)
    assert p.size == 513
    for level in range(p.max_level + 1):
        for k in p.keys(level):
            x0, y0, x1, y1 = p.clip(k)
            assert x1 <= 4990 and y1 <= 2990 and x1 > x0 and y1 > y0
    assert not p.exists(TileKey(0, 7, 5))  # wholly in the padding
    with pytest.raises(TerrabenchError, match="does not exist"):
        p.tile(TileKey(0, 7, 5))
    with pytest.raises(TerrabenchError, match="power of two"):
        TilePyramid(hf, 100)


def _covers(a, b):
    """True if tile a's area contains tile b's area."""
    s = a.level - b.level
    return s >= 0 and (b.tx >> s) == a.tx and (b.ty >> s) == a.ty


def _selection_views(hf):
    w, d = hf.extent
    yield default_view(hf, 320, 180)
    for frac in (0.3, 0.5):
        x, y = w * frac, d * 0.5
        z = float(hf.ground_height(x, y)) + 300.0
        yield View([x, y, z], [x + w, y + 0.3 * d, z - 800], 60, 320, 180, 1.0, 1e6)


def test_selection_restricted_and_complete(puget_full, pyr):
    for view in _selection_views(puget_full):
        sel = select_tiles(pyr, view)
        keys = [s.key for s in sel]
        assert len(set(keys)) == len(keys)
        for a in keys:  # no overlaps
            assert not any(_covers(a, b) for b in keys if b != a)
        for s in sel:  # restricted: edge neighbours within one level
            k = s.key
            for bit, dx, dy in ((EDGE_W, -1, 0), (EDGE_E, 1, 0), (EDGE_S, 0, -1), (EDGE_N, 0, 1)):
                for o in keys:
                    lo, hi = pyr.aabb(o)
                    a_lo, a_hi = pyr.aabb(k)
                    touch_x = (dx == -1 and np.isclose(hi[0], a_lo[0])) or (dx == 1 and np.isclose(lo[0], a_hi[0]))
                    touch_y = (dy == -1 and np.isclose(hi[1], a_lo[1])) or (dy == 1 and np.isclose(lo[1], a_hi[1]))
                    overlap_y = min(hi[1], a_hi[1]) > max(lo[1], a_lo[1])
                    overlap_x = min(hi[0], a_hi[0]) > max(lo[0], a_lo[0])
                    if (touch_x and overlap_y) or (touch_y and overlap_x):
                        assert abs(o.level - k.level) <= 1, (k, o)
                        assert bool(s.coarser_edges & bit) == (o.level == k.level + 1)
            assert s.projected_error <= 2 / 3 or k.level == 0


def test_front_to_back_order(puget_full, pyr):
    for view in _selection_views(puget_full):
        sel = select_tiles(pyr, view)
        boxes = [pyr.aabb(s.key) for s in sel]
        e = view.eye
        for ia, (alo, ahi) in enumerate(boxes):
            for ib, (blo, bhi) in enumerate(boxes):
                if ia == ib:
                    continue
                for ax, other in ((0, 1), (1, 0)):
                    overlap = min(ahi[other], bhi[other]) > max(alo[other], blo[other])
                    a_front = (ahi[ax] <= blo[ax] and e[ax] < ahi[ax]) or (alo[ax] >= bhi[ax] and e[ax] > alo[ax])
                    if overlap and a_front:
                        assert ia < ib, f"{sel[ia].key} must come before {sel[ib].key}"


def test_culled_tiles_are_outside(puget_full, pyr):
    view = list(_selection_views(puget_full))[1]
    sel = [s.key for s in select_tiles(pyr, view)]
    culled = [k for k in pyr.keys(0) if not any(_covers(s, k) for s in sel)]
    assert culled, "the low view must cull some tiles"
    for k in culled:
        lo, hi = pyr.aabb(k)
        g = np.stack(np.meshgrid(*[np.linspace(lo[a], hi[a], 5) for a in range(3)], indexing="ij"), -1).reshape(-1, 3)
        p = view.project(g)
        rel = g - view.eye
        in_front = rel @ view.forward > view.near
        inside = (
            in_front
            & (p[:, 0] >= 0)
            & (p[:, 0] <= view.width)
            & (p[:, 1] >= 0)
            & (p[:, 1] <= view.height)
            & (p[:, 2] >= 0)
        )
        assert not inside.any(), k


def test_tau_drives_refinement(puget_full, pyr):
    v = default_view(puget_full, 320, 180)
    coarse = select_tiles(pyr, v, tau=8.0)
    fine = select_tiles(pyr, v, tau=0.25)
    assert np.mean([s.level for s in fine]) < np.mean([s.level for s in coarse])
    with pytest.raises(TerrabenchError, match="tau"):
        select_tiles(pyr, v, tau=0)


@pytest.mark.parametrize("dense", [True, False])
@pytest.mark.parametrize(
    "name, size, tile", [("puget", 257, 32), ("fbm", 257, 16), ("spike", 129, 8), ("cliff", 129, 4)]
)
def test_vectorised_selection_equals_the_per_tile_traversal(name, size, tile, dense):
    from tiletree_reference import select_tiles_by_traversal

    from hybrid.camera.flight import get_flight
    from hybrid.terrain.datasets import get_dataset

    hf = get_dataset(name, size=size)
    pyr = TilePyramid(hf, tile)
    checked = splits = 0
    for flight in ("flyover", "orbit", "dolly"):
        for view in get_flight(flight, hf, frames=6, width=240, height=135).views():
            for tau in (0.25, 2 / 3, 4.0):
                fast, slow = select_tiles(pyr, view, tau, dense=dense), select_tiles_by_traversal(pyr, view, tau)
                assert fast == slow  # the same tiles, order, distances, errors and edge levels
                checked += 1
                splits += len({s.level for s in fast}) > 1
    assert checked == 54 and splits > 10  # mixed-level selections (restriction, stitching) were seen


@pytest.mark.parametrize("rows, cols, tile", [(190, 131, 16), (70, 301, 8), (33, 33, 64)])
def test_dense_and_level_by_level_selections_agree_on_ragged_grids(rows, cols, tile):
    """A rectangle that fills its addressing square only in part (and one tile alone): the selection over every
    tile place at once gives what the level-by-level one and the per-tile traversal give."""
    from tiletree_reference import select_tiles_by_traversal

    from hybrid.camera.flight import get_flight
    from hybrid.terrain.datasets import get_dataset
    from hybrid.tiles.tile_table import square_tiles

    h = get_dataset("fbm", size=513).heights[:rows, :cols] * 3.0
    hf = HeightField(h, (20.0, 35.0))
    pyr = TilePyramid(hf, tile)
    assert sum(len(pyr.keys(lv)) for lv in range(pyr.max_level + 1)) < square_tiles(pyr) or pyr.max_level == 0
    seen = 0
    for flight in ("flyover", "orbit"):
        for view in get_flight(flight, hf, frames=5, width=200, height=120).views():
            for tau in (0.3, 2.0):
                dense = select_tiles(pyr, view, tau, dense=True)
                assert dense == select_tiles(pyr, view, tau, dense=False)
                assert dense == select_tiles_by_traversal(pyr, view, tau)
                seen += len({s.level for s in dense}) > 1
    assert pyr.max_level == 0 or seen > 3


def test_a_table_of_every_tile_place_is_refused_beyond_its_limit():
    from hybrid.camera.view import View
    from hybrid.tiles.tile_table import MAX_TABLE_TILES, square_tiles

    hf = HeightField(np.zeros((2, 4097), np.float32), 10.0)
    pyr = TilePyramid(hf, 2)
    assert square_tiles(pyr) > MAX_TABLE_TILES
    view = View(eye=(100.0, -500.0, 300.0), target=(2000.0, 5.0, 0.0))
    with pytest.raises(TerrabenchError, match=f"would hold {square_tiles(pyr)} places, beyond {MAX_TABLE_TILES}"):
        select_tiles(pyr, view, dense=True)
    assert len(select_tiles(pyr, view)) > 0  # the automatic choice walks it level by level


def test_a_thin_grid_costs_what_its_samples_do():
    import tracemalloc

    h = np.random.default_rng(0).normal(100.0, 10.0, (2, 20000)).astype(np.float32)
    hf = HeightField(h, 30.0)
    tracemalloc.start()
    pyr = TilePyramid(hf, 256)
    tiles = [pyr.tile(k) for k in pyr.keys(0)]
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 100 * 2**20  # the addressing square (32769², 4 GiB) is never built
    assert len(tiles) == 79 and pyr.max_level == 7 and len(pyr.keys(pyr.max_level)) == 1
    assert sum(t.clip[2] - t.clip[0] for t in tiles) == pytest.approx(hf.extent[0])
    np.testing.assert_array_equal(tiles[3].heights[0], h[0, 3 * 256 : 4 * 256 + 1])
    np.testing.assert_array_equal(tiles[3].heights[5], h[1, 3 * 256 : 4 * 256 + 1])  # rows beyond repeat the edge
    with pytest.raises(TerrabenchError, match="padded square of 32769² samples"):
        _ = pyr.padded


def test_tile_samples_clamp_past_the_grid_as_indices_do():
    """Every tile of every level of grids that tiles do not divide: its samples equal the grid read at clamped
    (row, column) indices, every 2^l-th sample."""
    from hybrid.terrain.datasets import fbm

    for hf, n in ((fbm(300, seed=1), 64), (fbm(97, seed=2), 16), (fbm(129, seed=3), 32)):
        p = TilePyramid(hf, n)
        for level in range(p.max_level + 1):
            k = 1 << level
            steps = np.arange(n + 1) * k
            for key in p.keys(level):
                rows = np.minimum(key.ty * n * k + steps, hf.rows - 1)
                cols = np.minimum(key.tx * n * k + steps, hf.cols - 1)
                assert np.array_equal(p.samples(key), hf.heights[np.ix_(rows, cols)]), key
