"""The CPU part of a ray-cast tile's upload made in a tile store's loader thread: the same codes and max mipmap as
the GPU builder makes, kept beside the tile's samples until its upload takes them, and frames streamed from them
are the frames of a renderer that uploaded everything first, with no hole meanwhile."""

import threading
import time

import numpy as np
import pytest
from gl_memory import allocated_bytes
from raster_helpers import holes

from experiments.stream_jump import jump_views
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.terrain.grid_sources import FractalSource
from hybrid.tiles.store import StorePyramid, prepare_store
from raycast import caster
from raycast.gpu_tile import code_mips, prepare_heights, upload_heights, upload_prepared
from raycast.maxmip import MaxMipBuilder, maxmip_levels, read_maxmip
from raycast.mip_buffer import read_mip_buffer

SIZE = (160, 90)


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    return prepare_store(FractalSource(257, seed=3), tmp_path_factory.mktemp("prep") / "s", 32)


@pytest.mark.parametrize("n", [2, 4, 32, 256])
def test_code_mips_are_the_max_mipmap_of_the_codes(n):
    q = np.random.default_rng(n).integers(0, 65536, (n + 1, n + 1)).astype(np.uint16)
    got, want = code_mips(q), maxmip_levels(q)[1:]
    assert len(got) == len(want) and all(a.dtype == np.uint16 and np.array_equal(a, b) for a, b in zip(got, want))


def test_a_prepared_upload_equals_the_gpu_built_one(ctx):
    h = (np.random.default_rng(1).normal(size=(65, 65)) * 100).astype(np.float32)
    builder = MaxMipBuilder(ctx)
    a, b = upload_prepared(ctx, prepare_heights(h)), upload_heights(ctx, builder, h)
    try:
        assert (a.offset, a.step, a.base, a.quant_error) == (b.offset, b.step, b.base, b.quant_error)
        assert a.nbytes == allocated_bytes(a) and b.nbytes == allocated_bytes(b)
        assert a.heights.read() == b.heights.read()
        got, want = read_mip_buffer(a.maxmip, 64), read_maxmip(b.maxmip, 64)
        assert len(got) == len(want) == 6 and all(np.array_equal(x, y) for x, y in zip(got, want))
    finally:
        for g in (a, b):
            g.release()
        builder.release()


def test_the_loader_prepares_a_tile_once_and_its_tile_takes_it(store):
    p = StorePyramid(store)
    key = p.keys(0)[5]
    made = threading.Event()
    p.request([key], {key: [lambda: p.derive(key, "codes", prepare_heights) or made.set()]})
    assert p.idle(30) and made.is_set() and p.derived_keys([key], "codes") == {key}
    held = p.cache_bytes
    tile = p.tile(key)
    host = tile.host["codes"]
    want = prepare_heights(p.samples(key), p.hf.source_step)
    assert np.array_equal(host.codes.q, want.codes.q) and host.codes.offset == want.codes.offset
    assert p.cache_bytes == held - host.nbytes and not p.derived_keys([key], "codes")
    assert p.tile(key).host == {}  # handed over once
    p.close()


def test_uploads_of_a_jump_take_the_loaders_products_and_draw_the_resident_frame(ctx, store, monkeypatch):
    """Each frame waits for the loader: every ray-cast upload takes the codes it made (none is prepared in the
    frame's thread), no frame has a hole, and the drained frame is the resident renderer's."""
    p = StorePyramid(store)
    before, (v,) = jump_views(p.hf, 1, SIZE)
    resident = StorePyramid(store)
    with Renderer(ctx, resident.hf, "raycast", 32, pyramid=resident) as full:
        want = full.render(v, 2 / 3, mode="shaded")
    with ReferenceRenderer(ctx, p.hf) as ref:
        rf = ref.render(v, mode="shaded")
    in_frame = []
    real = caster.prepare_heights
    monkeypatch.setattr(
        caster, "prepare_heights", lambda *a: in_frame.append(threading.current_thread().name) or real(*a)
    )
    with Renderer(ctx, p.hf, "raycast", 32, pyramid=p, upload_budget_ms=0.0) as r:
        r.render(before, 2 / 3)  # the root and one tile, prepared in the frame: the loader has not run yet
        frames, in_frame[:] = [], []
        for _ in range(want.stats.tiles + 2):
            assert p.idle(60)
            res = r.render(v, 2 / 3, mode="shaded")
            frames.append(res.stats.fallback_tiles)
            assert holes(res, rf, v, p.hf) <= 1e-3 * res.distance.size
            if res.stats.fallback_tiles == 0:
                break
    p.close()
    assert frames[0] > 2 and frames == sorted(frames, reverse=True) and frames[-1] == 0
    assert in_frame and set(in_frame) == {"terrabench-tile-loader"}  # no upload prepared its codes itself
    assert np.array_equal(res.colour, want.colour)
    both = np.isfinite(want.distance)
    assert np.array_equal(np.isfinite(res.distance), both) and np.array_equal(res.distance[both], want.distance[both])


def test_no_loader_work_runs_inside_a_hold(store, monkeypatch):
    """A hold waits for the tile the loader is on, then nothing of the loader's runs until it ends."""
    from hybrid.tiles import store as store_mod

    monkeypatch.setattr(store_mod, "HOLD_WAIT_S", 60.0)  # wait for the step, however slow the machine
    p = StorePyramid(store)
    spans, lock = [], threading.Lock()

    def work():
        t0 = time.perf_counter()
        time.sleep(0.002)
        with lock:
            spans.append((t0, time.perf_counter()))

    keys = p.keys(0)
    p.request(keys, {k: [work] for k in keys})
    while not spans:
        time.sleep(0.001)
    with p.held():
        t0 = time.perf_counter()
        time.sleep(0.05)
        t1 = time.perf_counter()
    assert p.idle(60) and len(spans) == len(keys)
    assert not [s for s in spans if s[1] > t0 and s[0] < t1]
    p.close()
