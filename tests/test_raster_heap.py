"""The raster strategies' resident tiles in shared heaps (raster.heap) and their one-dispatch selection: each
tile's slot holds its heights and node block as uploaded, also after the heap grew and after eviction made it
smaller and moved its tiles; frames drawn after that are the frames drawn before. (One tile drawn as many items
of a frame, each clipped to a missing tile's rectangle: test_uploads' first frames, all drawn from the root.)"""

import numpy as np
import pytest

from hybrid.camera.flight import preset
from hybrid.renderer import Renderer
from raster.heap import MIN_SLOTS
from raster.indexed import IndexedTileletStrategy
from raster.nodes import nodes_for, tile_node_block

SIZE = (160, 96)


def slot_contents(g) -> tuple[np.ndarray, np.ndarray]:
    """(heights, node rows) read back from a tile's heap slot."""
    heap, s = g.slot.heap, g.slot
    h = np.frombuffer(heap.heights.read(size=4 * heap.height_words, offset=4 * s.heights_base), np.float32)
    nd = np.frombuffer(heap.nodes.read(size=16 * heap.node_rows, offset=16 * s.nodes_base), np.float32)
    return h.reshape(g.n + 1, g.n + 1), nd.reshape(-1, 4)


def test_slots_hold_their_tiles_through_growth_and_compaction(ctx, puget257):
    from hybrid.tiles.pyramid import TilePyramid

    pyr = TilePyramid(puget257, 32)
    s = IndexedTileletStrategy(ctx, puget257)
    try:
        keys = pyr.keys(0)[:20]
        tiles = {k: pyr.tile(k) for k in keys}
        gs = {k: s.upload(t) for k, t in tiles.items()}
        heap = s.heaps[32]
        assert heap.capacity >= 20 > MIN_SLOTS  # grew from MIN_SLOTS by copies on the GPU
        nodes = nodes_for(puget257, 32, s.beta)

        def check(k):
            h, nd = slot_contents(gs[k])
            np.testing.assert_array_equal(h, np.asarray(tiles[k].heights, np.float32))
            np.testing.assert_array_equal(nd, tile_node_block(nodes, k.level, k.tx, k.ty, 32)[0])

        for k in keys:
            check(k)
        before = heap.capacity
        for k in keys[:17]:
            gs.pop(k).release()
        assert heap.capacity < before and heap.used == 3  # compacted: fewer slots, tiles moved down
        assert sorted(g.slot.index for g in gs.values()) == [0, 1, 2]
        for k in gs:
            check(k)
        assert heap.spare_nbytes == (heap.capacity - 3) * heap.slot_bytes
    finally:
        s.release()


@pytest.mark.parametrize("strategy", ["raster", "raster_gs"])
def test_frames_after_eviction_equal_frames_before(ctx, puget257, strategy):
    fly = preset("flyover", puget257, 6, *SIZE)
    runs = [(fly.view(1), 0.5), (fly.view(2), 60.0), (fly.view(1), 0.5)]
    with Renderer(ctx, puget257, strategy, tile_size=32) as full:
        want = full.render(*runs[0])
    need = []
    for v, tau in runs[:2]:
        with Renderer(ctx, puget257, strategy, tile_size=32) as probe:
            probe.render(v, tau)
            need.append(probe.cache.bytes)
    budget = int(max(need) * 1.05)
    with Renderer(ctx, puget257, strategy, tile_size=32, budget_bytes=budget) as r:
        out = [r.render(v, tau) for v, tau in runs]
        assert r.cache.stats.evictions > 0
    assert np.isfinite(want.distance).sum() > 0.5 * want.distance.size
    np.testing.assert_array_equal(out[0].colour, want.colour)
    np.testing.assert_array_equal(out[2].colour, want.colour)  # drawn again from moved and new slots
    np.testing.assert_array_equal(out[2].distance, want.distance)


def test_one_selection_of_tiles_of_two_cell_counts_is_refused_by_name(ctx, puget257):
    from hybrid.errors import TerrabenchError
    from hybrid.tiles.pyramid import TilePyramid
    from hybrid.tiles.tiletree import select_tiles

    view = preset("flyover", puget257, 6, *SIZE).view(2)
    s = IndexedTileletStrategy(ctx, puget257)
    try:
        items = []
        for size in (32, 64):
            pyr = TilePyramid(puget257, size)
            sel = select_tiles(pyr, view)[0]
            items.append((s.upload(pyr.tile(sel.key)), pyr.tile(sel.key), sel))
        assert set(s.heaps) == {32, 64}
        with pytest.raises(TerrabenchError, match="one cell count, got \\[32, 64\\]"):
            s.select_leaves(view, items, 2 / 3)
    finally:
        s.release()


@pytest.mark.parametrize("policy", ["raster", "hybrid"])
def test_a_streaming_renderers_heaps_hold_the_budget_from_the_start(ctx, puget257, policy):
    """With an upload budget (streaming), the raster heap is made with room for the GPU budget of tiles and one
    more (a hybrid's two raster strategies fill that one heap), and neither grows nor shrinks as tiles come and go
    within the budget; without, it starts at MIN_SLOTS."""
    fly = preset("flyover", puget257, 6, *SIZE)
    with Renderer(ctx, puget257, "raster", tile_size=32) as probe:
        probe.render(fly.view(1), 0.5)
        slot = next(iter(probe.strategies["raster"].heaps.values())).slot_bytes
        assert all(h.capacity in {MIN_SLOTS << k for k in range(16)} for h in probe.strategies["raster"].heaps.values())
    budget = 12 * slot
    runs = [(fly.view(1), 0.5), (fly.view(3), 0.5), (fly.view(5), 60.0), (fly.view(1), 0.5)]
    with Renderer(ctx, puget257, policy, tile_size=32, budget_bytes=budget, upload_budget_ms=1e3) as r:
        pooled = [s for s in r.strategies.values() if hasattr(s, "heaps")]
        assert len(pooled) == (2 if policy == "hybrid" else 1)
        for v, tau in runs:
            r.render(v, tau)
            assert all(s.heaps is pooled[0].heaps for s in pooled)
            for heap in pooled[0].heaps.values():  # made at the first raster tile's upload
                assert heap.capacity == budget // slot + 1
        if policy == "raster":
            assert r.cache.stats.evictions > 0 and r.cache.bytes <= budget


def test_a_streaming_hybrid_whose_choices_lean_one_way_keeps_its_heap(ctx, puget257):
    """A streaming hybrid whose frames give every tile to one raster strategy, then every tile to the other, keeps
    its one heap at the size the budget made it (either strategy may fill it), draws what the pure strategy draws,
    and counts the heap's spare bytes once."""
    fly = preset("flyover", puget257, 6, *SIZE)
    view, tau = fly.view(3), 0.5
    with Renderer(ctx, puget257, "raster", tile_size=32) as probe:
        probe.render(view, tau)
        slot = next(iter(probe.strategies["raster"].heaps.values())).slot_bytes
    budget = 24 * slot
    with Renderer(ctx, puget257, "hybrid", tile_size=32, budget_bytes=budget, upload_budget_ms=1e3) as r:
        for name in ("raster", "raster_gs", "raster"):
            plans = r.plan(view, tau)
            # more than half the pool (pools of half the budget each would grow), all of it resident
            assert budget // slot // 2 < len(plans) < budget // slot
            for p in plans:
                p.choice = name
            got = r.render(view, tau, plans=plans)
            (heap,) = r.strategies[name].heaps.values()
            assert heap.capacity == budget // slot + 1
            assert r.strategies["raster"].heaps is r.strategies["raster_gs"].heaps
            with Renderer(ctx, puget257, name, tile_size=32) as pure:
                want = pure.render(view, tau)
            assert np.array_equal(got.colour, want.colour)
        spare = [r.strategies[n].spare_nbytes for n in ("raster", "raster_gs")]
        assert heap.spare_nbytes > 0 and sorted(spare) == [0, heap.spare_nbytes]


def test_a_streaming_heap_holds_no_more_than_every_tile_of_the_pyramid(ctx, puget257):
    fly = preset("flyover", puget257, 6, *SIZE)
    with Renderer(ctx, puget257, "raster", tile_size=32, budget_bytes=1 << 30, upload_budget_ms=1e3) as r:
        r.render(fly.view(1), 0.5)
        p = r.pyramid
        tiles = sum(a * b for a, b in (p.tile_counts(lev) for lev in range(p.max_level + 1)))
        (heap,) = r.strategies["raster"].heaps.values()
        assert tiles == 85 and heap.capacity == tiles + 1


def test_heaps_are_shared_only_before_an_upload_and_over_one_slot_layout(ctx, puget257):
    """Sharing another strategy's heaps is refused by name after a first upload, or where the slots' layout (beta)
    differs; where allowed, both strategies' tiles land in one heap."""
    from hybrid.errors import TerrabenchError
    from hybrid.tiles.pyramid import TilePyramid
    from raster.tilelets import TileletStrategy

    pyr = TilePyramid(puget257, 32)
    key = pyr.keys(0)[0]
    owner, other = IndexedTileletStrategy(ctx, puget257), TileletStrategy(ctx, puget257, beta=0.25)
    late, sharer = IndexedTileletStrategy(ctx, puget257), TileletStrategy(ctx, puget257)
    try:
        with pytest.raises(TerrabenchError, match="one beta"):
            other.share_heaps(owner)
        g = late.upload(pyr.tile(key))
        with pytest.raises(TerrabenchError, match="before its first upload"):
            late.share_heaps(owner)
        g.release()
        sharer.share_heaps(owner)
        a, b = owner.upload(pyr.tile(key)), sharer.upload(pyr.tile(key))
        assert a.slot.heap is b.slot.heap and a.slot.index != b.slot.index
        a.release()
        b.release()
    finally:
        for s in (owner, other, late, sharer):
            s.release()
