"""The raster strategies' node arrays of a periodic extension, served from its source store's: never below the exact
arrays of the extension's whole grid (``global_nodes`` in memory), equal to them away from the seams, saturated and
nested as the restricted quadtree needs, read a window at a time, and drawn without holes."""

import numpy as np
import pytest
from raster_helpers import border_views, holes
from test_store import ArraySource

from hybrid.errors import TerrabenchError
from hybrid.terrain import stored as stored_mod
from hybrid.terrain.grid_sources import FractalSource
from hybrid.tiles import store_nodes
from hybrid.tiles.fans import block2, dilate4
from hybrid.tiles.periodic import open_periodic
from hybrid.tiles.periodic_blocks import PeriodicBlocks, period_residue, source_block_tile
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.sidecodes import decoded_sides
from hybrid.tiles.store import prepare_store
from hybrid.tiles.store_blocks import band_blocks
from raster import nodes as nodes_mod
from raster.nodes import global_nodes, nodes_for, square_nodes, tile_node_block
from raster.quadtree import error_pyramid


def _rough(size=129, seed=3, period=None):
    """Rough synthetic heights (features of 32 cells, 800 m of relief); with ``period`` seamless."""
    return FractalSource(size, seed=seed, feature_cells=32, relief=800.0, period=period)


def _levels(nodes, g):
    return [np.asarray(a[g][:, :]) for a in (nodes.effective, nodes.zlo, nodes.zhi)]


def _far_from_seams(total, T, real):
    """Per node index of a level: local index 1..T-3 in its period, over the grid (not the padding)."""
    a = np.arange(total)
    return (a % T >= 1) & (a % T <= T - 3) & (a < real)


def _check_against_exact(ext, n, P, exact_levels):
    """Every node's effective error >= the exact one (of nodes that split on their full fans' errors: so also >= the
    side errors facing it over beta), its side codes read back never below its exact side errors, boxes containing
    the exact ones, equal away from the seams (bit for bit up to nodes of ``exact_levels``, codes where the parent
    is away too), saturated and nested; returns the exact and served nodes."""
    ref, got = square_nodes(ext.load(), n), nodes_for(ext, n)
    sides = error_pyramid(TilePyramid(ext.load(), n).padded, got.beta).sides
    assert got.cells == ref.cells and len(got.effective) == len(ref.effective) and got.beta == ref.beta
    periods = (ext.cols - 1) // P
    top = len(ref.effective) - 1
    for g in range(top + 1):
        (e, lo, hi), (re, rlo, rhi) = _levels(got, g), _levels(ref, g)
        assert e.dtype == lo.dtype == np.float32 and e.shape == re.shape, g
        assert np.all(e >= re) and np.all(lo <= rlo) and np.all(hi >= rhi), g
        w = np.asarray(got.sides[g][:, :])
        read = decoded_sides(w, _levels(got, g + 1)[0] if g < top else None)
        assert np.all(read >= sides[g]), g  # a dropped midpoint's error is bounded
        T = P >> (g + 1)
        if T >= 4:
            far = _far_from_seams(e.shape[0], T, periods * T)
            at = np.ix_(far, far)
            assert np.array_equal(lo[at], rlo[at]) and np.array_equal(hi[at], rhi[at]), g
            if g < exact_levels:
                assert np.array_equal(e[at], re[at]), g
            if g + 1 < exact_levels and T >= 8:
                both = far & _far_from_seams(e.shape[0] // 2, T // 2, periods * T // 2).repeat(2)
                assert np.array_equal(w[np.ix_(both, both)], np.asarray(ref.sides[g])[np.ix_(both, both)]), g
        if g:
            pe, plo, phi = _levels(got, g - 1)
            need = block2(dilate4(pe.astype(np.float64)), np.max) / got.beta
            assert np.all(e >= need * (1 - 1e-6)), g  # saturated: no crack between nodes
            assert np.all(lo <= block2(plo, np.min)) and np.all(hi >= block2(phi, np.max)), g  # boxes nested
    return ref, got


@pytest.mark.parametrize("periods", [2, 3, 4])
def test_periodic_node_arrays_bound_the_exact_ones_and_equal_them_off_the_seams(tmp_path, periods):
    prepare_store(_rough(), tmp_path / "s", 16)
    ext = open_periodic(tmp_path / "s", 128 * periods + 1)
    assert ext.store.attrs["nodes"]["periodic"] and ext.store.attrs["nodes"]["square"] == 128 * (
        4 if periods > 2 else 2
    )
    _check_against_exact(ext, 16, 128, 99)


def test_a_seamless_source_gives_the_exact_finest_errors_at_the_seams(tmp_path):
    """Near a seam a node holds the combined form's bound (both fans in one error): with no seam step that is the
    exact combined error at level 0, and the side-error form's elsewhere."""
    prepare_store(_rough(period=128), tmp_path / "s", 32)
    ext = open_periodic(tmp_path / "s", 513)
    ref, got = _check_against_exact(ext, 32, 128, 99)
    combined = square_nodes(ext.load(), 32, side_errors=False)
    e, re, ce = _levels(got, 0)[0], _levels(ref, 0)[0], _levels(combined, 0)[0]
    seam = (np.arange(e.shape[0]) % 64 == 63) & (np.arange(e.shape[0]) < 256)
    near = seam[:, None] | seam[None, :]
    assert np.allclose(e[near], ce[near], rtol=1e-5, atol=1e-6)  # no seam step, no saturation at level 0
    assert np.array_equal(e[~near], re[~near])
    e, ce = _levels(got, 3)[0].astype(np.float64), _levels(combined, 3)[0].astype(np.float64)
    assert np.median(e / np.maximum(ce, 1e-3)) < 1.01  # near the seams too, mostly


def test_bounded_source_levels_stay_bounds_in_the_extension(tmp_path, monkeypatch):
    monkeypatch.setattr(store_nodes, "NODE_EXACT_SPAN", 32)  # source nodes of 64 cells and up bounded
    prepare_store(_rough(seed=5), tmp_path / "s", 16)
    _check_against_exact(open_periodic(tmp_path / "s", 385), 16, 128, 4)


def test_seam_corner_pits_and_peaks_are_in_the_boxes(tmp_path):
    h = _rough(seed=7).read_rows(0, 129)
    h[0, 0], h[128, 128], h[0, 128] = h.min() - 900.0, h.max() + 900.0, h.min() - 300.0
    prepare_store(ArraySource(h, 10.0), tmp_path / "s", 16)
    _check_against_exact(open_periodic(tmp_path / "s", 257), 16, 128, 99)


@pytest.mark.parametrize("periods", [2, 3])
def test_every_tile_block_reads_bounds_of_the_exact_block(tmp_path, periods):
    prepare_store(_rough(seed=2), tmp_path / "s", 16)
    ext = open_periodic(tmp_path / "s", 128 * periods + 1)
    ref, got = global_nodes(ext.load(), 16), nodes_for(ext, 16)
    pyr = TilePyramid(ext.load(), 16)
    for level in range(pyr.max_level + 1):
        for key in pyr.keys(level):
            (a, ao), (b, bo) = (tile_node_block(x, level, key.tx, key.ty, 16) for x in (got, ref))
            # side codes (the fourth column) bound the sides where they are read: checked on the arrays
            assert np.array_equal(ao, bo) and np.array_equal(a[:, 3] > 0, b[:, 3] > 0), key
            assert np.all(a[:, 0] >= b[:, 0]) and np.all(a[:, 1] <= b[:, 1]) and np.all(a[:, 2] >= b[:, 2]), key


def _cut(nodes, level, tx, ty):
    return band_blocks(nodes.effective, nodes.zlo, nodes.zhi, level, ty, 16, tx, tx + 1, nodes.sides)[0]


def test_tile_blocks_away_from_the_seams_are_the_sources_and_equal_the_cut_ones(tmp_path):
    prepare_store(_rough(seed=2), tmp_path / "s", 16)
    ext = open_periodic(tmp_path / "s", 128 * 3 + 1)
    got = nodes_for(ext, 16)
    assert isinstance(got.blocks, PeriodicBlocks)
    # a row and a column of level 0 (8 tiles a period), a row of every coarser level
    keys = (
        [(0, tx, 11) for tx in range(24)]
        + [(0, 3, ty) for ty in range(24)]
        + [(1, tx, 5) for tx in range(12)]
        + [(level, tx, 0) for level in (2, 3, 4) for tx in range(24 >> level)]
    )
    reused = 0
    for level, tx, ty in keys:
        block = tile_node_block(got, level, tx, ty, 16)[0]
        assert np.array_equal(block, _cut(got, level, tx, ty)), (level, tx, ty)  # the source's is the extension's
        reused += source_block_tile(level, tx, ty, 16, 128, 384) is not None
    # level 0: residues 2..4 in the row (ty 11: residue 3) and the column; from level 1 every tile has a node
    # (apron included) at local index T-2, T-1 or 0 of some node level, so every block is cut
    assert reused == 9 + 9 and source_block_tile(0, 3, 11, 16, 128, 384) == (3, 3)


def test_blocks_cut_near_seams_repeat_every_period_inside_the_extension(tmp_path):
    prepare_store(_rough(seed=4), tmp_path / "s", 16)
    ext = open_periodic(tmp_path / "s", 128 * 5 + 1)  # periods 1..3 are inside
    got = nodes_for(ext, 16)
    for level, tx, ty in ((0, 8, 8), (0, 15, 9), (0, 12, 15), (1, 4, 7), (2, 3, 2), (3, 1, 1)):
        span = 16 << level
        shift = max(128 // span, 1)  # a period, in tiles of this level
        where = period_residue(level, tx, ty, 16, 128, 640)
        assert where is not None and source_block_tile(level, tx, ty, 16, 128, 640) is None
        first = _cut(got, level, tx, ty)
        for dx, dy in ((shift, 0), (0, shift), (shift, shift)):
            if (tx + dx + 1) * span > 512 or (ty + dy + 1) * span > 512:
                continue
            assert period_residue(level, tx + dx, ty + dy, 16, 128, 640) == where
            assert np.array_equal(_cut(got, level, tx + dx, ty + dy), first), (level, tx + dx, ty + dy)
            assert np.array_equal(tile_node_block(got, level, tx + dx, ty + dy, 16)[0], first)
    assert period_residue(0, 7, 8, 16, 128, 640) is None and period_residue(0, 8, 32, 16, 128, 640) is None


def test_a_large_extension_serves_tile_windows_without_building_a_level(tmp_path):
    import tracemalloc

    prepare_store(_rough(257), tmp_path / "s", 64)
    ext = open_periodic(tmp_path / "s", 256 * 256 + 1)  # 65537²: 32768² nodes at level 0
    tracemalloc.start()
    try:
        nodes = nodes_for(ext, 64)
        assert nodes.effective[0].shape == (32768, 32768) and nodes.cells == 65536
        top = int(ext.store.attrs["max_level"])
        blocks = [
            tile_node_block(nodes, lev, tx, ty, 64)[0]
            for lev, tx, ty in (
                (top, 0, 0),
                (top - 3, 3, 5),
                (2, 0, 0),
                (0, 3, 3),
                (0, 4, 4),
                (0, 1023, 1023),
                (1, 7, 2),
            )
        ]
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 32 * 2**20, peak  # a level 0 would be 4 GiB
    for b in blocks:
        assert np.all(np.isfinite(b)) and np.all(b[:, 1] <= b[:, 2]) and np.all(b[:, 0] >= 0)
    with pytest.raises(TerrabenchError, match="a window at a time"):
        np.asarray(nodes.effective[0])


def test_an_extension_of_a_store_without_node_arrays_is_loaded_or_refused_by_the_source_path(tmp_path, monkeypatch):
    import shutil

    import zarr

    prepare_store(_rough(), tmp_path / "old", 16)
    g = zarr.open_group(str(tmp_path / "old"), mode="r+")  # as a store prepared before node arrays
    del g.attrs["nodes"]
    del g.attrs["manifest"]  # (and so before manifests)
    shutil.rmtree(tmp_path / "old" / "nodes")
    ext = open_periodic(tmp_path / "old", 257)
    assert "nodes" not in ext.store.attrs
    assert nodes_for(ext, 16).cells == 256  # small: built over the loaded grid
    monkeypatch.setattr(nodes_mod, "MAX_LOAD_SAMPLES", 1000)
    with pytest.raises(TerrabenchError, match=f"{tmp_path / 'old'}: .*without the raster.*--out {tmp_path / 'old'} "):
        nodes_for(open_periodic(tmp_path / "old", 257), 16)
    prepare_store(_rough(), tmp_path / "new", 16)
    with pytest.raises(TerrabenchError, match=f"{tmp_path / 'new'}: node arrays were prepared for tiles of 16"):
        nodes_for(open_periodic(tmp_path / "new", 257), 32)


@pytest.mark.parametrize("period", [128, None])
@pytest.mark.parametrize("full_res", ["exact", "lean"])
def test_a_periodic_extension_draws_with_the_raster_strategies_without_holes(
    ctx, tmp_path, monkeypatch, period, full_res
):
    # seamless, and with seam cliffs (rough borders between tiles of different levels: morph on and off)
    from hybrid.reference import ReferenceRenderer
    from hybrid.renderer import Renderer

    prepare_store(_rough(seed=4, period=period), tmp_path / "s", 16)
    ext = open_periodic(tmp_path / "s", 385)
    whole = ext.load()
    views = border_views(ext)  # along x = 128 cells: a seam
    with ReferenceRenderer(ctx, whole) as ref:
        refs = [ref.render(v, mode="shaded") for v in views]
    with Renderer(ctx, whole, "raster", 16) as mem:
        counts = [mem.render(v, morph=False, full_res=full_res).stats.counters["triangles"] for v in views]
    monkeypatch.setattr(stored_mod, "MAX_LOAD_SAMPLES", 1000)  # nothing may gather the grid now
    for policy in ("raster", "raster_gs"):
        with Renderer(ctx, ext, policy, 16) as r:
            for v, rf, count in zip(views, refs, counts):
                for morph in (True, False):
                    res = r.render(v, mode="shaded", morph=morph, full_res=full_res)
                    assert holes(res, rf, v, whole) == 0, (policy, morph)
                    assert res.stats.counters["triangles"] >= count > 0  # nodes split no later than exact ones
