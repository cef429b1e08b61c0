"""Tile stores: built out of core, equal to the in-memory pyramid, resumable, read on demand within a host budget,
refusing what they cannot be, and drawn by the renderer without holes."""

import json

import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin

from hybrid.errors import TerrabenchError
from hybrid.terrain.datasets import puget
from hybrid.terrain.grid_sources import FractalSource, GdalGridSource
from hybrid.terrain.heightfield import HeightField
from hybrid.terrain.stored import open_store
from hybrid.tiles import store_prepare as store_mod
from hybrid.tiles.periodic import open_periodic
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.quantize import dequantize, quantize
from hybrid.tiles.store import StorePyramid, prepare_store


class ArraySource:
    """A grid source over an in-memory array (the tests' oracle input)."""

    def __init__(self, h, spacing, source_step=None):
        self.h, self.rows, self.cols, self.spacing, self.name, self.notes = h, h.shape[0], h.shape[1], spacing, "a", []
        self.reads, self.source_step = 0, source_step

    def read_rows(self, r0, r1):
        self.reads += 1
        return self.h[r0:r1]


@pytest.fixture(scope="module")
def grid():
    hf = puget(size=257)
    return np.ascontiguousarray(hf.heights[:250, :211]), (hf.spacing_x, hf.spacing_y)


def test_store_equals_the_in_memory_pyramid(grid, tmp_path):
    h, sp = grid
    prepare_store(ArraySource(h, sp), tmp_path / "s", 32)
    stored, mem = StorePyramid(tmp_path / "s"), TilePyramid(HeightField(h, sp), 32)
    assert stored.max_level == mem.max_level == 3
    for level in range(mem.max_level + 1):
        assert np.array_equal(stored._zmin[level], mem._zmin[level])
        assert np.array_equal(stored._zmax[level], mem._zmax[level])
        assert np.allclose(stored._err[level], mem._err[level], rtol=1e-9, atol=1e-9)  # exact at these spans
        for key in mem.keys(level):
            a, b = stored.tile(key), mem.tile(key)
            assert np.array_equal(a.heights, b.heights) and a.clip == b.clip and a.error == b.error, key


def test_error_bound_above_exact_span_is_never_below_the_exact_error(grid, tmp_path, monkeypatch):
    h, sp = grid
    monkeypatch.setattr(store_mod, "EXACT_SPAN", 32)  # levels >= 1 of tiles of 32: bounded
    prepare_store(ArraySource(h, sp), tmp_path / "s", 32)
    stored, mem = StorePyramid(tmp_path / "s"), TilePyramid(HeightField(h, sp), 32)
    assert np.allclose(stored._err[1], mem._err[1])  # level 1 against level 0 is exact either way
    loose = 1.0
    for level in (2, 3):
        assert np.all(stored._err[level] >= mem._err[level] - 1e-6)
        loose = max(loose, float((stored._err[level] / np.maximum(mem._err[level], 1e-9)).max()))
    assert loose > 1.0  # the bound is a bound, not the exact value


def test_prepare_resumes_after_an_interruption_and_refuses_other_input(grid, tmp_path):
    h, sp = grid
    src = ArraySource(h, sp)
    with pytest.raises(KeyboardInterrupt):
        prepare_store(src, tmp_path / "s", 32, stop_after=5)
    with pytest.raises(TerrabenchError, match="incomplete"):
        open_store(tmp_path / "s")
    first = src.reads
    prepare_store(src, tmp_path / "s", 32)
    assert src.reads - first == -(-(h.shape[0] - 1) // 32) - 5  # level 0's remaining bands only
    whole = tmp_path / "w"
    prepare_store(ArraySource(h, sp), whole, 32)
    a, b = StorePyramid(tmp_path / "s"), StorePyramid(whole)
    for level in range(a.max_level + 1):
        assert np.array_equal(a._err[level], b._err[level]) and np.array_equal(a._zmax[level], b._zmax[level])
        for key in a.keys(level):
            assert np.array_equal(a.tile(key).heights, b.tile(key).heights)
    with pytest.raises(TerrabenchError, match="other input or settings"):
        prepare_store(ArraySource(h, sp), whole, 64)
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "x.txt").write_text("x")
    with pytest.raises(TerrabenchError, match="not a tile store"):
        prepare_store(ArraySource(h, sp), tmp_path / "busy", 32)


def test_tiles_on_demand_within_a_host_budget_and_a_loader_thread(grid, tmp_path):
    h, sp = grid
    prepare_store(ArraySource(h, sp), tmp_path / "s", 32)
    tile_bytes = 33 * 33 * 4
    p = StorePyramid(tmp_path / "s", host_bytes=3 * tile_bytes)
    keys = p.keys(0)
    assert p.cache_bytes == 0  # opening reads no tile
    for k in keys[:5]:
        p.tile(k)
    assert p.stats["reads"] == 5 and p.stats["evictions"] == 2 and p.cache_bytes == 3 * tile_bytes
    assert [p.cached(k) for k in keys[:5]] == [False, False, True, True, True]
    p.tile(keys[4])
    assert p.stats["hits"] == 1
    assert p.request(keys[5:8]).wait(10)
    assert all(p.cached(k) for k in keys[5:8]) and p.stats["peak_bytes"] <= 3 * tile_bytes


def test_neighbouring_tiles_decode_each_chunk_once(grid, tmp_path):
    h, sp = grid
    prepare_store(ArraySource(h, sp), tmp_path / "s", 32)
    p, mem = StorePyramid(tmp_path / "s", host_bytes=64 << 20), TilePyramid(HeightField(h, sp), 32)
    chunks = 0
    for level in range(mem.max_level + 1):
        for key in mem.keys(level):  # a tile's apron comes from its neighbours' chunks, decoded before
            assert np.array_equal(p.tile(key).heights, mem.tile(key).heights), key
        rows, cols = p._levels[level].shape
        chunks += -(-rows // 32) * -(-cols // 32)
    assert p.stats["chunk_reads"] == chunks  # every chunk of every level decoded once
    tiles = sum(len(mem.keys(level)) for level in range(mem.max_level + 1))
    assert p.cache_bytes == tiles * 33 * 33 * 4 + p.chunk_bytes and 0 < p.chunk_bytes <= p.chunk_budget


def test_geotiffs_in_two_crs_prepare_like_loading_them_whole(tmp_path):
    from hybrid.terrain.loaders import load_terrain

    h = puget(size=129).heights[::-1]  # north-up rows as a file stores them
    for crs, transform in (
        ("EPSG:32610", from_origin(500000, 5200000, 30, 30)),
        ("EPSG:4326", from_origin(-122.5, 47.5, 1 / 3600, 1 / 3600)),
    ):
        path = tmp_path / f"{crs.replace(':', '')}.tif"
        with rasterio.open(
            path,
            "w",
            driver="GTiff",
            height=h.shape[0],
            width=h.shape[1],
            count=1,
            dtype="float32",
            crs=crs,
            transform=transform,
        ) as dst:
            dst.write(h.astype(np.float32), 1)
        src = GdalGridSource(path)
        whole = load_terrain(path)
        assert (src.rows, src.cols) == whole.heights.shape
        assert np.allclose(src.spacing, (whole.spacing_x, whole.spacing_y))
        assert np.array_equal(np.concatenate([src.read_rows(0, 50), src.read_rows(50, src.rows)]), whole.heights)
        out = prepare_store(src, tmp_path / f"{crs.replace(':', '')}.store", 32)
        t = open_store(out)
        assert np.allclose((t.spacing_x, t.spacing_y), (whole.spacing_x, whole.spacing_y))
        assert np.array_equal(t.heights[:, :], whole.heights)


def _stepped(size=129, seed=5):
    """Rough heights on a 0.1 m step with a 5 m offset, as a 16-bit DEM scaled: float32(5 + 0.1 k), k in int16."""
    rng = np.random.default_rng(seed)
    k = np.cumsum(np.cumsum(rng.integers(-40, 41, (size, size)), axis=0), axis=1)
    k = np.clip(k - k.min() - 20000, -32768, 32767).astype(np.int16)
    return (5.0 + 0.1 * k.astype(np.float64)).astype(np.float32)


def test_a_store_keeps_its_source_height_step_and_its_16_bit_tiles_are_exact(tmp_path):
    h = _stepped()
    prepare_store(ArraySource(h, 10.0, source_step=(0.1, 5.0)), tmp_path / "s", 32)
    t = open_store(tmp_path / "s")
    assert t.source_step == (0.1, 5.0) and t.load().source_step == (0.1, 5.0)
    for terrain in (t, open_periodic(tmp_path / "s", 385)):  # the extension's samples are the source's
        assert terrain.source_step == (0.1, 5.0)
        pyr = StorePyramid(terrain)
        for level in range(pyr.max_level + 1):
            for key in pyr.keys(level):
                tile = pyr.tile(key)
                z = quantize(tile.heights, terrain.source_step)
                back = dequantize(z.q, z.offset, z.step, z.base)
                assert z.error == 0.0 and np.array_equal(back.view(np.uint32), tile.heights.view(np.uint32)), key
                assert pyr.quantization_error(key) == 0.0, key
    # a float source has no step: quantised lossily, the error bounded and added to the tiles' errors
    prepare_store(ArraySource(h + np.float32(0.013), 10.0), tmp_path / "f", 32)
    f = StorePyramid(tmp_path / "f")
    assert f.hf.source_step is None and open_periodic(tmp_path / "f", 257).source_step is None
    key = f.root()
    assert quantize(f.tile(key).heights).error > 0 and f.quantization_error(key) >= quantize(f.tile(key).heights).error
    # a claimed step one sample is off is not recorded
    off = h.copy()
    off[100, 7] += np.float32(0.04)
    prepare_store(ArraySource(off, 10.0, source_step=(0.1, 5.0)), tmp_path / "o", 32)
    assert open_store(tmp_path / "o").source_step is None
    with pytest.raises(TerrabenchError, match="source_step must"):
        prepare_store(ArraySource(h, 10.0, source_step=(0.0, 5.0)), tmp_path / "bad", 32)


def test_a_store_without_a_recorded_step_reads_as_one_without_step(tmp_path):
    import zarr

    prepare_store(ArraySource(_stepped(65), 10.0, source_step=(0.1, 5.0)), tmp_path / "s", 32)
    g = zarr.open_group(str(tmp_path / "s"), mode="r+")  # as a store written before the attribute
    del g.attrs["source_step"]
    assert open_store(tmp_path / "s").source_step is None
    assert StorePyramid(tmp_path / "s").quantization_error(StorePyramid(tmp_path / "s").root()) > 0


def test_a_16_bit_geotiff_source_carries_its_step_into_the_store(tmp_path):
    from hybrid.terrain.loaders import load_terrain

    k = np.arange(65 * 65, dtype=np.int16).reshape(65, 65) % 977
    path = tmp_path / "dem.tif"
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        height=65,
        width=65,
        count=1,
        dtype="int16",
        crs="EPSG:32610",
        transform=from_origin(500000, 5200000, 30, 30),
    ) as dst:
        dst.write(k, 1)
        dst.scales = (0.1,)
    src = GdalGridSource(path)
    assert src.source_step == load_terrain(path).source_step == (0.1, 0.0)
    t = open_store(prepare_store(src, tmp_path / "s", 32))
    assert t.source_step == (0.1, 0.0) and StorePyramid(t).quantization_error(StorePyramid(t).root()) == 0.0


def test_nodata_is_refused_by_name(tmp_path):
    h = np.ones((40, 40), np.float32)
    h[5, 7] = -9999
    path = tmp_path / "holes.tif"
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        height=40,
        width=40,
        count=1,
        dtype="float32",
        crs="EPSG:32610",
        transform=from_origin(0, 400, 10, 10),
        nodata=-9999,
    ) as dst:
        dst.write(h, 1)
    with pytest.raises(TerrabenchError, match=r"1 no-data samples.*fill them first"):
        prepare_store(GdalGridSource(path), tmp_path / "s", 16)
    out = tmp_path / "s"
    assert not out.exists() or not json.loads((out / "zarr.json").read_text())["attributes"]["complete"]


def test_synthetic_terrain_is_window_and_size_independent(tmp_path):
    """A fractal's samples depend on neither the rows read at once nor the grid's size; the prepare's memory is
    measured in test_store_nodes.test_prepare_memory_stays_band_sized."""
    a = FractalSource(257, seed=0)
    whole = a.read_rows(0, 257)
    assert np.array_equal(whole, np.concatenate([a.read_rows(0, 100), a.read_rows(100, 257)]))
    assert not np.array_equal(whole, FractalSource(257, seed=1).read_rows(0, 257))
    assert whole.max() - whole.min() > 30 and np.isfinite(whole).all()
    prepare_store(FractalSource(513, seed=0), tmp_path / "s", 64)
    t = open_store(tmp_path / "s")
    assert t.heights.shape == (513, 513) and np.array_equal(t.heights[:257, :257], whole)


@pytest.mark.gl
def test_a_store_renders_as_its_grid_does(ctx, grid, tmp_path):
    from hybrid.camera.flight import preset
    from hybrid.renderer import Renderer

    h, sp = grid
    prepare_store(ArraySource(h, sp), tmp_path / "s", 32)
    stored, mem = open_store(tmp_path / "s"), HeightField(h, sp)
    v = preset("flyover", mem, 6, 160, 90).view(2)
    assert np.allclose(preset("flyover", stored, 6, 160, 90).view(2).eye, v.eye)  # presets read it lazily
    for policy in ("raycast", "raster"):
        with Renderer(ctx, stored, policy, 32) as a, Renderer(ctx, mem, policy, 32) as b:
            x, y = a.render(v), b.render(v)
        assert np.array_equal(x.colour, y.colour), policy
    with pytest.raises(TerrabenchError, match="prepared with tiles of 32"):
        Renderer(ctx, stored, "raycast", 64)


def test_close_stops_the_loader_thread_and_frees_the_host_cache(grid, tmp_path):
    h, sp = grid
    prepare_store(ArraySource(h, sp), tmp_path / "s", 32)
    p = StorePyramid(tmp_path / "s")
    keys = p.keys(0)
    assert p.request(keys[:4]).wait(10) and p.cache_bytes > 0
    p.request(keys)  # still reading when closed
    loader = p._loader
    p.close()
    assert not loader.is_alive()
    assert p.cache_bytes == 0 and not p.cached(keys[0])
    assert p.request(keys[:2]).wait(10) and p.cached(keys[1])  # a new loader on the next request
    p.close()


def test_a_paused_loader_reads_nothing_until_let_go(grid, tmp_path):
    """A paused loader thread holds before its next tile (the scaling run pauses every store but the one timed);
    let go, it reads what it was asked; closing a paused loader ends it."""
    h, sp = grid
    prepare_store(ArraySource(h, sp), tmp_path / "s", 32)
    p = StorePyramid(tmp_path / "s")
    keys = p.keys(0)
    assert p.request(keys[:1]).wait(10)
    p.pause()
    done = p.request(keys[1:4])
    assert not done.wait(0.3) and not any(p.cached(k) for k in keys[2:4])
    p.pause(False)
    assert done.wait(10) and all(p.cached(k) for k in keys[1:4])
    p.pause()
    p.request(keys[4:])
    loader = p._loader
    p.close()  # ends though paused
    assert not loader.is_alive()
