"""What each structure pays to follow an edit equals a full rebuild: the pyramid, the max mipmap, the node arrays."""

import numpy as np
import pytest

from hybrid.terrain.datasets import crop, get_dataset, puget
from hybrid.terrain.edits import Crater, Raise, Smooth, Window, apply_brush, brush_params
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.tile_table import tile_table


@pytest.fixture(scope="module")
def small_puget():
    return crop(puget(with_texture=False), 97)  # 16-bit source: tiles exact on the step until edited


def _edit(hf, brushes):
    """Apply brushes to hf's heights in place; the union of their windows."""
    win = None
    for b in brushes:
        w = apply_brush(hf.heights, brush_params(b, hf))
        win = w if win is None else win.union(w)
    return win


def _pyramid_arrays(p):
    out = []
    for level in range(p.max_level + 1):
        rows, cols = p.tile_counts(level)
        ty, tx = np.divmod(np.arange(rows * cols), cols)
        out += [
            *p.level_arrays(level),
            p.level_table(level),
            p.quantization_errors_at(level, tx, ty),
        ]
    return out


@pytest.mark.parametrize(("name", "cached"), [("puget", "all"), ("fbm", "all"), ("puget", "one level")])
def test_pyramid_after_edits_equals_a_rebuild(small_puget, name, cached):
    hf = crop(small_puget, 97) if name == "puget" else get_dataset("fbm", 97)
    p = TilePyramid(hf, 16)
    if cached == "all":
        _pyramid_arrays(p)  # every cache made before the edit
        tile_table(p)
    else:  # level 1's only: the others made after it, from the edited heights
        p.level_table(1)
        p.quantization_errors_at(1, np.zeros(1, np.int64), np.zeros(1, np.int64))
    cx, cy = hf.origin[0] + 32 * hf.spacing_x, hf.origin[1] + 48 * hf.spacing_y
    win = _edit(
        hf,
        [
            Raise((cx, cy), 9 * hf.spacing_x, 40.0),
            Crater((cx + 30 * hf.spacing_x, cy), 6 * hf.spacing_x, 25.0),
            Smooth((hf.origin[0], hf.origin[1]), 5 * hf.spacing_x, 1.0),
        ],
    )
    keys = p.follow_edit(win)
    fresh = TilePyramid(hf, 16)
    for a, b in zip(_pyramid_arrays(p), _pyramid_arrays(fresh), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(tile_table(p).boxes, tile_table(fresh).boxes)
    assert hf.height_range == (float(hf.heights.min()), float(hf.heights.max()))
    assert {k.level for k in keys} == set(range(p.max_level + 1))
    assert len([k for k in keys if k.level == 0]) < len(p.keys(0))  # not every tile


def test_touched_keys_include_both_tiles_of_a_shared_border():
    hf = get_dataset("fbm", 65)
    p = TilePyramid(hf, 16)
    win = _edit(hf, [Raise((16 * 30.0, 40 * 30.0), 20.0, 5.0)])  # one sample: the border column 16
    assert (win.j0, win.j1, win.i0, win.i1) == (16, 17, 40, 41)
    level0 = sorted((k.tx, k.ty) for k in p.touched_keys(win) if k.level == 0)
    assert level0 == [(0, 2), (1, 2)]


def test_max_mipmap_updated_over_the_window_equals_a_rebuild():
    from hybrid.terrain.edits import Window
    from raycast.maxmip import maxmip_levels, update_levels

    rng = np.random.default_rng(4)
    h = rng.integers(0, 60000, (65, 65)).astype(np.uint16)
    levels = maxmip_levels(h)
    for win in (Window(10, 14, 40, 41), Window(0, 3, 0, 65), Window(63, 65, 62, 65), Window(31, 34, 31, 34)):
        h[win.slices()] = rng.integers(0, 65535, (win.i1 - win.i0, win.j1 - win.j0))
        update_levels(levels, h, win)
        for a, b in zip(levels, maxmip_levels(h), strict=True):
            np.testing.assert_array_equal(a, b)


def test_local_window_of_a_coarse_tile_includes_its_repeated_edge_samples():
    from hybrid.terrain.edits import Window
    from hybrid.tiles.pyramid import TileKey
    from raycast.edit import local_window

    # a 90-sample grid, tiles of 16 cells: the level-2 tile (1, 0) starts at column 64, samples every 4th
    assert local_window(Window(0, 3, 70, 75), TileKey(2, 1, 0), 16, 90, 90) == Window(0, 1, 2, 3)
    assert local_window(Window(0, 3, 88, 90), TileKey(2, 1, 0), 16, 90, 90) == Window(0, 1, 6, 17)
    assert local_window(Window(5, 7, 0, 2), TileKey(0, 0, 0), 16, 90, 90) == Window(5, 7, 0, 2)


def test_gpu_max_mipmap_updated_over_the_window_equals_a_rebuild(ctx):
    """The host's max-mip texels over each changed window, written level by level into the tile's buffer, against
    the GPU builder's whole max mipmap of the changed codes."""
    from hybrid.terrain.edits import Window
    from raycast.gpu_tile import code_mips
    from raycast.maxmip import MaxMipBuilder, read_maxmip, texel_windows
    from raycast.mip_buffer import mip_buffer, read_mip_buffer, write_mip_rows

    rng = np.random.default_rng(5)
    n = 64
    h = rng.integers(0, 60000, (n + 1, n + 1)).astype(np.uint16)
    b = MaxMipBuilder(ctx)
    ht = ctx.texture((n + 1, n + 1), 1, h.tobytes(), dtype="u2")
    buf = mip_buffer(ctx, code_mips(h))
    try:
        for win in (Window(10, 14, 40, 41), Window(0, 3, 0, 65), Window(63, 65, 62, 65)):
            h[win.slices()] = rng.integers(60000, 65535, (win.i1 - win.i0, win.j1 - win.j0))
            part = np.ascontiguousarray(h[win.slices()])
            ht.write(part.tobytes(), viewport=(win.j0, win.i0, win.j1 - win.j0, win.i1 - win.i0))
            write_mip_rows(buf, code_mips(h), texel_windows(n, win))
            full = b.build(ht, n)
            for got, want in zip(read_mip_buffer(buf, n), read_maxmip(full, n), strict=True):
                np.testing.assert_array_equal(got, want)
            full.release()
        assert read_mip_buffer(buf, n)[-1][0, 0] >= 60000
    finally:
        for o in (ht, buf, b):
            o.release()


@pytest.mark.parametrize("exact_span", [1024, 8])  # 8: levels of bounded errors too
def test_node_arrays_after_edits_equal_a_rebuild(monkeypatch, exact_span):
    import raster.rect_nodes as rn
    from raster.node_edit import node_edits, update_nodes
    from raster.nodes import GlobalNodes

    monkeypatch.setattr(rn, "EXACT_SPAN", exact_span)
    hf = get_dataset("fbm", 97)  # tiles of 16: a 128-cell square, so padding classes beyond the grid
    R, eff, zlo, zhi, sides = rn.rect_nodes(hf, 16, 0.9)
    nodes = GlobalNodes(
        R,
        0.9,
        tuple(a.copy() for a in eff),
        tuple(a.copy() for a in zlo),
        tuple(a.copy() for a in zhi),
        sides=tuple(a.copy() for a in sides),
    )
    st = node_edits(hf, 16, 0.9)
    edits = [
        Raise((16 * 30.0, 32 * 30.0), 100.0, 60.0),  # across a tile border
        Crater((96 * 30.0, 96 * 30.0), 200.0, 40.0),  # the grid's corner: padding classes change
        Smooth((50 * 30.0, 20 * 30.0), 150.0, 1.0),
    ]
    for brush in edits:
        win = _edit(hf, [brush])
        rewritten = update_nodes(st, nodes, hf, win)
        want = rn.rect_nodes(hf, 16, 0.9)
        for got_arrays, want_arrays in zip((nodes.effective, nodes.zlo, nodes.zhi, nodes.sides), want[1:], strict=True):
            for g, (a, b) in enumerate(zip(got_arrays, want_arrays, strict=True)):
                np.testing.assert_array_equal(a, b, err_msg=f"level {g} after {brush}")
        assert rewritten[0].i1 - rewritten[0].i0 < nodes.effective[0].shape[0]  # not the whole level 0
    assert not np.array_equal(nodes.zhi[0], zhi[0]) and not np.array_equal(nodes.effective[2], eff[2])


def test_a_replaced_resident_tile_keeps_its_slot_and_its_bytes_count(ctx):
    from hybrid.residency import ResidencyCache
    from hybrid.strategies import make_strategy

    hf = get_dataset("fbm", 65)
    p = TilePyramid(hf, 16)
    keys = [*p.keys(0)[:2], p.root()]
    s = make_strategy("raycast", ctx, hf)
    cache = ResidencyCache()
    try:
        for k in keys:
            cache.get("raycast", s, k, lambda k=k: p.tile(k))
        new = s.upload(p.tile(keys[1]))
        cache.replace("raycast", keys[1], new)
        resident = cache.resident("raycast")
        assert [k for k, _ in resident] == keys and resident[1][1] is new
        assert cache.bytes == sum(int(g.nbytes) for _, g in resident) > 0
        assert cache.stats.uploads == 3  # a replacement is no upload of a new tile
    finally:
        cache.clear()
        s.release()


def test_compiled_deviation_blocks_equal_the_array_form():
    """Per-block deviation maxima of a coarse level's surface, compiled, against the whole-array numpy form
    (``hybrid.tiles.bounds``: deviations, corner maxima, block maxima), bit for bit: whole grids and windows, grids
    that blocks do not divide."""
    from hybrid.tiles.bounds import _corner, _deviation, _reduce
    from hybrid.tiles.bounds_loops import deviation_block_max

    for h in (crop(get_dataset("puget"), 257).heights, get_dataset("fbm", 300).heights, get_dataset("fbm", 97).heights):
        cells_r, cells_c = h.shape[0] - 1, h.shape[1] - 1
        for k in (2, 4, 16, 64):
            rows, cols = -(-cells_r // k), -(-cells_c // k)
            for a0, a1, b0, b1 in ((0, rows, 0, cols), (1, min(5, rows), 2, min(7, cols))):
                i0, i1, j0, j1 = a0 * k, min(a1 * k, cells_r), b0 * k, min(b1 * k, cells_c)
                want = _reduce(_corner(_deviation(h, k, i0, i1, j0, j1), np.maximum), k, np.maximum)
                np.testing.assert_array_equal(deviation_block_max(h, k, a0, a1, b0, b1), want)


def test_deviation_blocks_follow_windows_on_and_beside_block_borders():
    """Each level's deviation blocks after an edit of a window whose edges fall on, just before or just after a
    block border equal the blocks of the edited grid measured whole: the blocks re-measured are all it moved."""
    from hybrid.tiles import pyramid_edit as pedit

    hf = get_dataset("fbm", 97)
    p = TilePyramid(hf, 16)
    rng = np.random.default_rng(3)
    windows = [(16, 17, 32, 33), (15, 16, 47, 49), (31, 34, 0, 2), (64, 65, 63, 66), (95, 97, 8, 9), (0, 1, 96, 97)]
    for i0, i1, j0, j1 in windows:
        hf.heights[i0:i1, j0:j1] += rng.uniform(5.0, 50.0, (i1 - i0, j1 - j0)).astype(np.float32)
        p.follow_edit(Window(i0, i1, j0, j1))
        whole = pedit.level_blocks(hf.heights, p.max_level, p.n)
        for level in whole.dev:
            np.testing.assert_array_equal(p._dev_blocks.dev[level], whole.dev[level], err_msg=f"{level} {i0} {j0}")
            np.testing.assert_array_equal(p._dev_blocks.sup[level], whole.sup[level])
