"""The CPU part of a raster tile's upload (its node block and per-level extremes) made in a tile store's loader
thread: an upload that takes it holds what an upload made in the frame holds, a product made for another tile is
not taken, streamed frames take the loader's products and end as the resident renderer's frame, and a
write-through drops every product a loader made before it."""

import shutil
import threading

import numpy as np
import pytest
from test_store import ArraySource

import raster.selection as selection
from experiments.stream_jump import jump_views
from hybrid.editing import TerrainEditor
from hybrid.renderer import Renderer
from hybrid.strategies import make_strategy
from hybrid.terrain.datasets import puget
from hybrid.terrain.edits import Crater
from hybrid.terrain.grid_sources import FractalSource
from hybrid.terrain.stored import open_store
from hybrid.tiles.store import StorePyramid, prepare_store

N = 32
SIZE = (160, 90)


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    return prepare_store(FractalSource(257, seed=3), tmp_path_factory.mktemp("prep") / "s", N)


def _slot_bytes(g) -> tuple[bytes, bytes]:
    """(heights, node rows) bytes of a resident tile's heap slot, read back from the GPU."""
    heap, i = g.slot.heap, g.slot.index
    hb, nb = 4 * heap.height_words, 16 * heap.node_rows
    return heap.heights.read(hb, offset=i * hb), heap.nodes.read(nb, offset=i * nb)


def _tile(pyr, key, host=None):
    t = pyr.tile(key)
    t.host.clear()
    if host is not None:
        t.host[selection.TileletSelection.host_product] = host
    return t


def test_an_upload_of_the_loaders_nodes_equals_one_made_in_the_frame(ctx, store):
    p = StorePyramid(store)
    s = make_strategy("raster", ctx, p.hf)
    try:
        keys = [p.keys(0)[3], p.keys(1)[2], p.keys(p.max_level)[0]]
        for key in keys:
            made = s.host_prepare(p.samples(key), None, key=key)
            a, b = s.upload(_tile(p, key, made)), s.upload(_tile(p, key))
            assert _slot_bytes(a) == _slot_bytes(b)
            assert (a.block, a.numbers, a.side_errors) == (b.block, b.numbers, b.side_errors)
            assert np.array_equal(a.offsets, b.offsets) and np.array_equal(a.starts, b.starts)
            # another tile's product is not taken: the upload makes its own
            c = s.upload(_tile(p, key, s.host_prepare(p.samples(keys[0]), None, key=p.keys(0)[0])))
            assert _slot_bytes(c) == _slot_bytes(b) and c.numbers == b.numbers
            for g in (a, b, c):
                g.release()
    finally:
        s.release()
        p.close()


def test_streamed_raster_uploads_take_the_loaders_nodes_and_end_as_the_resident_frame(ctx, store, monkeypatch):
    """Each frame waits for the loader: no raster upload makes its node block in the frame's thread, and the drained
    frame is the frame of a renderer that uploaded every tile first."""
    p = StorePyramid(store)
    before, (v,) = jump_views(p.hf, 1, SIZE)
    resident = StorePyramid(store)
    with Renderer(ctx, resident.hf, "raster", N, pyramid=resident) as full:
        want = full.render(v, 2 / 3, mode="shaded")
    threads = []
    real = selection.host_nodes
    monkeypatch.setattr(selection, "host_nodes", lambda *a: threads.append(threading.current_thread().name) or real(*a))
    with Renderer(ctx, p.hf, "raster", N, pyramid=p, upload_budget_ms=0.0) as r:
        r.render(before, 2 / 3)  # the root and one tile, made in the frame: the loader has not run yet
        threads[:] = []
        for _ in range(want.stats.tiles + 2):
            assert p.idle(60)
            res = r.render(v, 2 / 3, mode="shaded")
            if res.stats.fallback_tiles == 0:
                break
    p.close()
    assert res.stats.fallback_tiles == 0
    assert threads and set(threads) == {"terrabench-tile-loader"}  # no upload made its nodes itself
    assert np.array_equal(res.colour, want.colour)


def test_a_write_through_drops_every_product_the_loader_made_before_it(ctx, tmp_path):
    src = puget(size=161)
    h, sp = np.ascontiguousarray(src.heights), (src.spacing_x, src.spacing_y)
    path = prepare_store(ArraySource(h, sp), tmp_path / "tpl", N)
    shutil.copytree(path, tmp_path / "s")
    st = open_store(tmp_path / "s")
    p = StorePyramid(st)
    with Renderer(ctx, st, "raster", N, pyramid=p) as r:
        s = r.strategies["raster"]
        keys = p.keys(0)
        for key in keys:
            p.derive(key, s.host_product, lambda h, step, k=key: s.host_prepare(h, step, key=k))
        assert p.derived_keys(keys, s.host_product) == set(keys)
        held = r.tile(keys[-1])  # a tile made before the edit holds its product until its upload
        assert s.host_product in held.host
        ox, oy, _ = st.origin
        with TerrainEditor(ctx, st, r) as editor:
            touched = editor.apply(Crater((ox + 40 * 160.0, oy + 64 * 160.0), 1200.0, 300.0)).tiles
        assert 0 < touched < len(keys)
        assert p.derived_keys(keys, s.host_product) == set()  # untouched tiles' too
        assert held.host == {}
    p.close()
