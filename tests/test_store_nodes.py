"""The raster strategies' node arrays in a tile store: equal to ``global_nodes`` of the grid in memory (nodes split on
their full fans' errors, with side codes; bit for bit where measured, never below where bounded), the combined form
(both fans in one error, for periodic extensions' seams) likewise, resumable, read a tile at a time, and drawn as the
grid is; a store prepared without them is refused by path."""

import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin
from test_store import ArraySource

from hybrid.errors import TerrabenchError
from hybrid.terrain import stored as stored_mod
from hybrid.terrain.datasets import puget
from hybrid.terrain.grid_sources import GdalGridSource
from hybrid.terrain.heightfield import HeightField
from hybrid.terrain.loaders import load_terrain
from hybrid.terrain.stored import open_store
from hybrid.tiles import store_nodes
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.sidecodes import decoded_sides
from hybrid.tiles.store import prepare_store
from raster.nodes import global_nodes, nodes_for, square_nodes, tile_node_block
from raster.quadtree import error_pyramid

SP = (30.0, 40.0)


def _arrays(nodes, lev):
    return [np.asarray(a[lev][:, :]) for a in (nodes.effective, nodes.zlo, nodes.zhi)]


def open_store_attrs(path):
    """A store's attributes, complete or not."""
    import zarr

    return zarr.open_group(str(path), mode="r").attrs


def _compare(store_path, hf, n, exact_span):
    """Assert the store's node arrays against the padded square's of hf (``square_nodes``): effective errors, combined errors and side codes
    equal up to nodes of exact_span cells (codes where the parent is too), the errors above never below the exact
    ones and the codes read back never below the exact side errors (ranges always equal); returns the largest
    bound / exact ratio."""
    import zarr

    ref, combined = square_nodes(hf, n), square_nodes(hf, n, side_errors=False)
    got = nodes_for(open_store(store_path), n)
    stored = zarr.open_group(str(store_path), mode="r")
    sides = error_pyramid(TilePyramid(hf, n).padded, got.beta).sides
    assert got.cells == ref.cells and len(got.effective) == len(ref.effective) and got.sides is not None
    loose, top = 1.0, len(ref.effective) - 1
    for lev in range(top + 1):
        (e, lo, hi), (re, rlo, rhi) = _arrays(got, lev), _arrays(ref, lev)
        c, rc = np.asarray(stored[f"nodes/combined/{lev}"][:, :]), combined.effective[lev]
        w = np.asarray(got.sides[lev][:, :])
        assert e.dtype == c.dtype == w.dtype == np.float32 and e.shape == re.shape == c.shape == w.shape, lev
        assert np.array_equal(lo, rlo) and np.array_equal(hi, rhi), lev
        assert np.all(decoded_sides(w, _arrays(got, lev + 1)[0] if lev < top else None) >= sides[lev]), lev
        if (2 << lev) <= exact_span:
            assert np.array_equal(e, re) and np.array_equal(c, rc), lev
            if lev == top or (4 << lev) <= exact_span:
                assert np.array_equal(w, ref.sides[lev]), lev
        else:
            assert np.all(e >= re) and np.all(c >= rc), lev
            loose = max(loose, float((e / np.maximum(re, 1e-6)).max()))
    return loose


@pytest.mark.parametrize("shape", [(513, 513), (300, 460)])
def test_node_arrays_equal_global_nodes_bit_for_bit(tmp_path, shape):
    h = np.ascontiguousarray(puget().heights[200 : 200 + shape[0], 100 : 100 + shape[1]])
    prepare_store(ArraySource(h, SP), tmp_path / "s", 64)
    hf = HeightField(h, SP)
    assert _compare(tmp_path / "s", hf, 64, 1 << 30) == 1.0  # every level measured: squares of 512 cells
    stored, ref = nodes_for(open_store(tmp_path / "s"), 64), global_nodes(hf, 64)
    pyr = TilePyramid(hf, 64)
    for level in range(pyr.max_level + 1):  # every tile's block, apron included
        for key in pyr.keys(level):
            a, b = (tile_node_block(x, level, key.tx, key.ty, 64) for x in (stored, ref))
            assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]), key


def test_bounded_levels_never_below_the_exact_errors(tmp_path, monkeypatch):
    h = puget(size=513).heights
    monkeypatch.setattr(store_nodes, "NODE_EXACT_SPAN", 128)  # blocks of 128 cells; nodes of 256, 512 bounded
    prepare_store(ArraySource(h, SP), tmp_path / "s", 64)
    assert open_store(tmp_path / "s").store.attrs["nodes"]["exact_span"] == 128
    assert _compare(tmp_path / "s", HeightField(h, SP), 64, 128) > 1.0  # a bound, not the exact value


def test_an_interrupted_node_build_resumes_to_the_same_arrays(tmp_path, monkeypatch):
    h = puget(size=257).heights
    monkeypatch.setattr(store_nodes, "NODE_EXACT_SPAN", 64)  # 4 direct bands, then bounded levels
    monkeypatch.setattr(store_nodes, "NODE_BAND", 512)  # levels 0, 1 in several bands
    prepare_store(ArraySource(h, SP), tmp_path / "whole", 32)
    level_bands = 8 + 4 + 2 + 1
    for stop in (level_bands + 2, 5, 3):  # in the direct bands, in level passes
        with pytest.raises(KeyboardInterrupt):
            prepare_store(ArraySource(h, SP), tmp_path / "s", 32, stop_after=stop)
        assert "nodes" not in dict(open_store_attrs(tmp_path / "s"))
    prepare_store(ArraySource(h, SP), tmp_path / "s", 32)
    a, b = nodes_for(open_store(tmp_path / "s"), 32), nodes_for(open_store(tmp_path / "whole"), 32)
    for lev in range(len(a.effective)):
        for x, y in zip(_arrays(a, lev), _arrays(b, lev)):
            assert np.array_equal(x, y), lev
    assert _compare(tmp_path / "s", HeightField(h, SP), 32, 64) >= 1.0
    assert not (tmp_path / "s" / "nodes" / "tmp").exists()


def test_a_store_without_node_arrays_is_refused_by_path_until_prepared_again(tmp_path):
    import shutil

    import zarr

    h = puget(size=129).heights
    prepare_store(ArraySource(h, SP), tmp_path / "old", 32)
    g = zarr.open_group(str(tmp_path / "old"), mode="r+")  # as a store prepared before node arrays
    del g.attrs["nodes"]
    del g.attrs["manifest"]  # (and so before manifests)
    g.attrs.update({"progress": {k: v for k, v in dict(g.attrs["progress"]).items() if not k.startswith("nodes")}})
    shutil.rmtree(tmp_path / "old" / "nodes")
    with pytest.raises(TerrabenchError, match=f"{tmp_path / 'old'}.*without the raster.*prepare again"):
        nodes_for(open_store(tmp_path / "old"), 32)
    prepare_store(ArraySource(h, SP), tmp_path / "old", 32)  # the same prepare adds them
    assert _compare(tmp_path / "old", HeightField(h, SP), 32, 1 << 30) == 1.0


@pytest.mark.slow
def test_prepare_memory_stays_band_sized(tmp_path, monkeypatch):
    import tracemalloc

    from hybrid.terrain.grid_sources import FractalSource
    from hybrid.tiles import store_prepare as store_mod

    peaks, build = {}, store_mod.build_nodes

    class Measured(Exception):
        """Both peaks taken: the rest of the prepare (tile blocks, read a window of rows at a time) is not run."""

    def measured(*a, **k):
        peaks["levels"] = tracemalloc.get_traced_memory()[1]
        tracemalloc.reset_peak()
        build(*a, **k)
        peaks["nodes"] = tracemalloc.get_traced_memory()[1]
        raise Measured

    monkeypatch.setattr(store_mod, "build_nodes", measured)
    tracemalloc.start()
    try:
        with pytest.raises(Measured):
            prepare_store(FractalSource(2049, seed=0), tmp_path / "s", 128)
    finally:
        tracemalloc.stop()
    # the grid as float64 is 32 MiB, its square of nodes 16 MiB a level: the node build holds one block of 1024²
    # cells and one band a level
    assert peaks["nodes"] < 100 * 2**20 and peaks["nodes"] <= peaks["levels"], peaks


def test_block_build_reads_node_arrays_a_bounded_window_at_a_time(monkeypatch):
    """RowWindows holds at most WINDOW_BYTES of whole rows (or the rows asked, if more), whatever the array's
    length, and serves every window asked with the array's samples."""
    from hybrid.tiles import store_blocks

    monkeypatch.setattr(store_blocks, "WINDOW_BYTES", 64 * 100 * 4)
    a = np.arange(1000 * 100, dtype=np.float32).reshape(1000, 100)
    w = store_blocks.RowWindows(a)
    held = 0
    for r0 in range(-1, 1000, 31):
        ra, rb = max(r0, 0), min(r0 + 35, 1000)
        assert np.array_equal(w[ra:rb, 3:97], a[ra:rb, 3:97])
        held = max(held, w.held.nbytes)
    assert held <= 64 * 100 * 4


@pytest.fixture(scope="module")
def puget_store(tmp_path_factory):
    """Bundled Puget Sound written as a north-up GeoTIFF and prepared into a store of tiles of 128."""
    d = tmp_path_factory.mktemp("puget")
    hf = puget()
    tif = d / "puget.tif"
    with rasterio.open(
        tif,
        "w",
        driver="GTiff",
        height=hf.rows,
        width=hf.cols,
        count=1,
        dtype="float32",
        crs="EPSG:32610",
        transform=from_origin(500000, 5300000, 160, 160),
    ) as dst:
        dst.write(np.ascontiguousarray(hf.heights[::-1]).astype(np.float32), 1)
    return prepare_store(GdalGridSource(tif), d / "puget.store", 128), load_terrain(tif)


def test_puget_store_nodes_equal_the_loaded_grid(puget_store):
    path, whole = puget_store
    assert _compare(path, whole, 128, 1 << 30) == 1.0


@pytest.mark.gl
def test_raster_frames_from_the_store_equal_the_grid_without_loading_it(ctx, puget_store, monkeypatch):
    from hybrid.camera.flight import preset
    from hybrid.renderer import Renderer

    path, whole = puget_store
    stored = open_store(path)
    monkeypatch.setattr(stored_mod, "MAX_LOAD_SAMPLES", 1000)  # nothing may gather the grid
    with pytest.raises(TerrabenchError, match="out of core"):
        stored.load()
    for k in (2, 5):
        v = preset("flyover", whole, 6, 160, 90).view(k)
        for policy in ("raster", "raster_gs"):
            with Renderer(ctx, stored, policy, 128) as a, Renderer(ctx, whole, policy, 128) as b:
                x, y = a.render(v), b.render(v)
            assert x.stats.counters["triangles"] == y.stats.counters["triangles"] > 0, policy
            assert np.isfinite(x.distance).any(), policy
            assert np.array_equal(x.colour, y.colour) and np.array_equal(x.distance, y.distance), (policy, k)


@pytest.mark.parametrize("window_bytes", [None, 1])
def test_stored_blocks_are_the_node_arrays_around_each_tile(tmp_path, monkeypatch, window_bytes):
    """Every tile's stored block holds, node by node, the node arrays' values (side codes in the fourth column) over
    the tile and its one-node apron (zeros and inside 0 beyond the node square): checked element by element, with
    the node arrays read whole or (``window_bytes`` 1) a window of one tile row's rows at a time."""
    from hybrid.tiles import store_blocks

    if window_bytes is not None:
        monkeypatch.setattr(store_blocks, "WINDOW_BYTES", window_bytes)
    h = puget(size=129).heights
    n = 16
    prepare_store(ArraySource(h, SP), tmp_path / "s", n)
    terrain = open_store(tmp_path / "s")
    assert terrain.store.attrs["node_blocks"]
    nodes = nodes_for(terrain, n)
    assert nodes.blocks is not None
    pyr = TilePyramid(HeightField(h, SP), n)
    for level in range(pyr.max_level + 1):
        arrays = {
            lev: _arrays(nodes, lev) + [np.asarray(nodes.sides[lev][:, :])] for lev in range(len(nodes.effective))
        }
        for key in pyr.keys(level):
            data, offsets = tile_node_block(nodes, level, key.tx, key.ty, n)
            for m in range(len(offsets) - 1):
                side = n >> (m + 1)
                grid = data[offsets[m] : offsets[m + 1]].reshape(side + 2, side + 2, 4)
                e, lo, hi, w = arrays[level + m]
                for a in range(-1, side + 1):
                    for b in range(-1, side + 1):
                        i, j = key.ty * side + a, key.tx * side + b
                        inside = 0 <= i < e.shape[0] and 0 <= j < e.shape[1]
                        want = (e[i, j], lo[i, j], hi[i, j], w[i, j]) if inside else (0.0, 0.0, 0.0, 0.0)
                        assert tuple(grid[a + 1, b + 1]) == want, (key, m, a, b)


def test_a_store_without_blocks_gets_them_from_prepare_and_draws_the_same(tmp_path):
    """A store whose node blocks are missing (made before them) reads its nodes by windows; running prepare on
    it again adds the blocks, and both give every tile the same block."""
    import zarr

    h = puget(size=129).heights
    prepare_store(ArraySource(h, SP), tmp_path / "s", 32)
    g = zarr.open_group(str(tmp_path / "s"), mode="r+")
    del g["nodes/blocks"]
    attrs = dict(g.attrs)
    attrs.pop("node_blocks")
    attrs.pop("manifest")  # a store made before blocks had no manifest either
    attrs["progress"] = {k: v for k, v in attrs["progress"].items() if not k.startswith("blocks:")}
    g.attrs.clear()
    g.attrs.update(attrs)
    windows = nodes_for(open_store(tmp_path / "s"), 32)
    assert windows.blocks is None
    prepare_store(ArraySource(h, SP), tmp_path / "s", 32)
    blocks = nodes_for(open_store(tmp_path / "s"), 32)
    assert blocks.blocks is not None
    pyr = TilePyramid(HeightField(h, SP), 32)
    for level in range(pyr.max_level + 1):
        for key in pyr.keys(level):
            a, b = (tile_node_block(x, level, key.tx, key.ty, 32) for x in (windows, blocks))
            assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]), key


@pytest.mark.parametrize("m", [0, 2, 4])
def test_side_maxima_over_row_windows_equal_the_whole_grid(m):
    """A store measures side errors in windows of a few sample rows, parts of a node row where the node is taller:
    put together they are the whole grid's, node by node and side by side."""
    from hybrid.tiles.fans import side_maxima

    rng = np.random.default_rng(m)
    dev = rng.random((65, 65))
    whole = side_maxima(dev, m)
    s, rows = 2 << m, 8
    got = np.zeros_like(whole)
    for r0 in range(0, 64, rows):
        part = side_maxima(dev[r0 : r0 + rows + 1], m, r0 % s if rows < s else 0)
        a = r0 // s
        np.maximum(got[:, a : a + part.shape[1]], part, out=got[:, a : a + part.shape[1]])
    assert np.array_equal(got, whole)


def test_a_store_prepared_before_side_codes_keeps_its_form_and_gets_blocks_of_it(tmp_path):
    """A store whose node arrays hold one error over both fans (no ``form``, no side codes) stays so when prepared
    again: its missing blocks are cut in that form (fourth column 1), and it reads without side codes."""
    import zarr

    h = puget(size=129).heights
    prepare_store(ArraySource(h, SP), tmp_path / "s", 32)
    g = zarr.open_group(str(tmp_path / "s"), mode="r+")
    combined = [np.asarray(g[f"nodes/combined/{lev}"][:, :]) for lev in range(int(g.attrs["nodes"]["levels"]))]
    for lev, c in enumerate(combined):  # the earlier form: its errors, no codes, no blocks
        g[f"nodes/effective/{lev}"][:, :] = c
    for name in ("nodes/sides", "nodes/combined", "nodes/blocks"):
        del g[name]
    attrs = dict(g.attrs)
    attrs.pop("node_blocks")
    attrs.pop("manifest")  # a store made before blocks had no manifest either
    attrs["nodes"] = {k: v for k, v in attrs["nodes"].items() if k != "form"}
    attrs["progress"] = {k: v for k, v in attrs["progress"].items() if not k.startswith("blocks:")}
    g.attrs.clear()
    g.attrs.update(attrs)
    prepare_store(ArraySource(h, SP), tmp_path / "s", 32)
    nodes = nodes_for(open_store(tmp_path / "s"), 32)
    assert nodes.blocks is not None and nodes.sides is None
    for lev, c in enumerate(combined):
        assert np.array_equal(np.asarray(nodes.effective[lev][:, :]), c), lev
    block = tile_node_block(nodes, 0, 1, 1, 32)[0]
    assert set(np.unique(block[:, 3]).tolist()) <= {0.0, 1.0} and (block[:, 3] == 1.0).any()
