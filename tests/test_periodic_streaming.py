"""Streaming a periodic extension: the slow host part of a near-seam tile's upload or triangle estimate (cutting its
node block from the extension's node arrays) runs in the store's loader thread, never inside a frame; the tile is
drawn from its resident ancestor (or ray cast, for the estimate) meanwhile, with no hole, and once the loader is done
the frame is the one a renderer that cut everything first draws."""

import threading

import numpy as np
import pytest
from raster_helpers import holes
from test_periodic_nodes import _rough

from hybrid.camera.view import View
from hybrid.cost.model import load_cost_model
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.tiles import periodic_blocks
from hybrid.tiles.periodic import open_periodic
from hybrid.tiles.store import StorePyramid, prepare_store
from raster import estimate as estimate_mod

SIZE = (160, 90)


def _seam_view(hf) -> View:
    """A low view along the seam at x = 128 cells, looking north."""
    w, d = hf.extent
    ox, oy, oz = hf.origin
    lo, hi = hf.height_range
    bx = ox + 128 * hf.spacing_x
    eye = np.array([bx, oy - 0.05 * d, oz + hi + 0.4 * (hi - lo) + 50])
    return View(eye, np.array([bx, oy + 0.6 * d, oz + lo]), 60, *SIZE, near=1.0, far=10 * w)


def _cuts(monkeypatch) -> list:
    """Spy on block cuts: (thread name, level, tx, ty) of each."""
    seen, real = [], periodic_blocks.band_blocks

    def spy(effective, zlo, zhi, level, ty, n, tx0, tx1, inside=None):
        seen.append((threading.current_thread().name, level, tx0, ty))
        return real(effective, zlo, zhi, level, ty, n, tx0, tx1, inside)

    monkeypatch.setattr(periodic_blocks, "band_blocks", spy)
    return seen


@pytest.mark.parametrize("policy", ["raster", "hybrid"])
def test_near_seam_blocks_are_cut_in_the_loader_thread_not_in_frames(ctx, tmp_path, monkeypatch, policy):
    prepare_store(_rough(seed=4), tmp_path / "s", 16)
    model = load_cost_model("llvmpipe") if policy == "hybrid" else None
    v = _seam_view(open_periodic(tmp_path / "s", 385))
    whole = open_periodic(tmp_path / "s", 385).load()
    with ReferenceRenderer(ctx, whole) as ref:
        rf = ref.render(v, mode="shaded")
    with Renderer(ctx, open_periodic(tmp_path / "s", 385), policy, 16, cost_model=model, adapt=False) as full:
        want = full.render(v, 2.0, mode="shaded")
        plans = full.plan(v, 2.0)
        choices = [p.choice for p in plans]
        estimates = [p.features.triangles for p in plans] if policy == "hybrid" else []
    ext = open_periodic(tmp_path / "s", 385)  # a fresh extension: nothing cut yet
    pyramid = StorePyramid(ext)
    cuts = _cuts(monkeypatch)
    heights_built = []
    real_nodes = estimate_mod.tile_nodes
    monkeypatch.setattr(estimate_mod, "tile_nodes", lambda *a: heights_built.append(a) or real_nodes(*a))
    with Renderer(ctx, ext, policy, 16, pyramid=pyramid, cost_model=model, adapt=False, upload_budget_ms=1e6) as r:
        history, gaps, unknown, waited = [], [], [], []
        for _ in range(50):
            res = r.render(v, 2.0, mode="shaded")
            history.append(res.stats)
            waited.append(len(r.triangles.waiting) if policy == "hybrid" else 0)  # estimates left to the loader
            # waiting tiles drawn from their ancestor: no hole but a few pixels where the ancestor meets finer
            # tiles unstitched (as in test_uploads); once drained the frame of the renderer that cut everything first
            gaps.append(holes(res, rf, v, whole))
            assert gaps[-1] <= 1e-3 * res.distance.size, gaps
            plans = r.plan(v, 2.0)
            unknown.append(int(np.isnan([p.features.triangles for p in plans] if policy == "hybrid" else []).sum()))
            if res.stats.pending_uploads == 0 and not unknown[-1]:
                break
            assert pyramid.idle(120)  # the loader has cut what this frame asked for
    root = pyramid.max_level
    in_frames = [c for c in cuts if c[0] != "terrabench-tile-loader"]
    loader = [c for c in cuts if c[0] == "terrabench-tile-loader"]
    assert loader and all(c[1] == root for c in in_frames), in_frames  # only the always-resident root
    assert not heights_built  # the estimate never fell back to the tile's heights
    assert history[0].fallback_tiles > 0 or policy == "hybrid"  # near-seam raster tiles waited
    assert res.stats.pending_uploads == 0 and res.stats.fallback_tiles == 0
    assert unknown[-1] == 0 and [p.choice for p in plans] == choices
    if policy == "hybrid":  # estimates waited for the loader, then caught up
        assert waited[0] > 0 and [p.features.triangles for p in plans] == estimates
    assert np.array_equal(res.colour, want.colour)
    both = np.isfinite(want.distance)
    assert np.array_equal(np.isfinite(res.distance), both) and np.array_equal(res.distance[both], want.distance[both])


def test_a_cut_reads_each_source_chunk_once_and_cuts_again_from_them(tmp_path, monkeypatch):
    from hybrid.tiles import source_chunks
    from raster.nodes import nodes_for

    monkeypatch.setattr(source_chunks, "WHOLE_BYTES", 0)  # every level read a chunk at a time
    prepare_store(_rough(seed=4), tmp_path / "s", 16)
    ext = open_periodic(tmp_path / "s", 385)
    blocks = nodes_for(ext, 16).blocks
    chunks = ext.store["nodes/effective/0"].nodes.source_chunks
    assert not blocks.ready(0, 7, 3)  # next to the seam at x = 128 cells
    first = blocks[0][3, 7].copy()
    reads = chunks.chunks.made
    assert 0 < reads == len(chunks.chunks) and blocks.ready(0, 7, 3)  # each chunk decoded once
    blocks.cut.clear()
    assert not blocks.ready(0, 7, 3)
    assert np.array_equal(blocks[0][3, 7], first) and chunks.chunks.made == reads  # no chunk read twice


def test_byte_lru_keeps_the_newest_within_its_bytes_and_makes_each_once():
    from hybrid.tiles.byte_lru import ByteLRU

    lru, made = ByteLRU(3 * 800), []
    make = lambda k: lambda: made.append(k) or np.full(100, k, np.float64)  # noqa: E731  (800 bytes)
    for k in (1, 2, 3):
        assert lru.get(k, make(k))[0] == k
    assert lru.get(1, make(1))[0] == 1 and made == [1, 2, 3]  # a hit makes nothing and refreshes 1
    lru.get(4, make(4))  # over budget: 2, the least recent, goes
    assert 2 not in lru and all(k in lru for k in (1, 3, 4)) and lru.nbytes == 2400
    big = ByteLRU(10)
    assert big.get("a", make(5))[0] == 5 and "a" in big and len(big) == 1  # the newest stays, even too big


def test_a_cut_reads_the_source_node_chunks_from_their_files_as_zarr_reads_them(tmp_path, monkeypatch):
    from hybrid.terrain import store_manifest
    from hybrid.tiles import source_chunks
    from raster.nodes import nodes_for

    monkeypatch.setattr(source_chunks, "WHOLE_BYTES", 0)  # every level read a chunk at a time
    prepare_store(_rough(seed=4), tmp_path / "s", 16)
    ext = open_periodic(tmp_path / "s", 385)
    chunks = ext.store["nodes/effective/0"].nodes.source_chunks
    cls, gets = store_manifest._checked_class(), []
    original_get = cls.get

    async def get(self, key, prototype=None, byte_range=None):
        gets.append(key)
        return await original_get(self, key, prototype, byte_range)

    monkeypatch.setattr(cls, "get", get)
    nodes_for(ext, 16).blocks[0][3, 7]  # a cut next to the seam
    assert len(chunks.chunks) > 0 and not [k for k in gets if "/c/" in k]  # no chunk read through Zarr
    for kind, g, cy, cx in list(chunks.chunks._items):
        arr = chunks.array(kind, g)
        ch, cw = arr.chunks
        want = np.asarray(arr[cy * ch : (cy + 1) * ch, cx * cw : (cx + 1) * cw], dtype=np.float32)
        assert chunks._chunk(kind, g, cy, cx).tobytes() == want.tobytes()


def test_cuts_from_whole_source_levels_equal_cuts_from_chunks_bit_for_bit(tmp_path, monkeypatch):
    from hybrid.tiles import source_chunks
    from raster.nodes import nodes_for

    prepare_store(_rough(seed=4), tmp_path / "s", 16)
    cut = {}
    for whole in (0, 1 << 30):  # every level read a chunk at a time, then every level whole
        monkeypatch.setattr(source_chunks, "WHOLE_BYTES", whole)
        ext = open_periodic(tmp_path / "s", 385)  # a fresh extension: nothing cut or kept yet
        blocks = nodes_for(ext, 16).blocks
        chunks = ext.store["nodes/effective/0"].nodes.source_chunks
        tiles = [(lev, tx, ty) for lev in range(3) for ty in range(0, 25 >> lev, 3) for tx in range(25 >> lev)]
        cut[whole] = {t: blocks[t[0]][t[2], t[1]].tobytes() for t in tiles if not blocks.ready(*t)}
        assert (len(chunks.chunks) > 0) == (whole == 0) and any(v is not None for v in chunks._whole.values()) == (
            whole > 0
        )
    assert len(cut[0]) > 20 and cut[0] == cut[1 << 30]
