"""Edits written through to a tile store: reopened, the store holds and draws what an in-memory edit gives; a crash
at any point of the write leaves it verifying and wholly before or after the edit; the write follows the edit."""

import shutil

import numpy as np
import pytest
from test_store import ArraySource

import hybrid.terrain.store_journal as journal
from experiments.cli.store_info import verify_store
from hybrid.camera.flight import preset
from hybrid.editing import TerrainEditor
from hybrid.errors import TerrabenchError
from hybrid.renderer import Renderer
from hybrid.terrain.datasets import puget
from hybrid.terrain.edits import Crater, Raise
from hybrid.terrain.heightfield import HeightField
from hybrid.terrain.stored import open_store
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.store import StorePyramid, prepare_store
from raster.nodes import global_nodes, nodes_for, tile_node_block

N = 32


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    """A prepared store of a 161² crop of Puget (tiles of 32) and its heights."""
    src = puget(size=161)
    h, sp = np.ascontiguousarray(src.heights), (src.spacing_x, src.spacing_y)
    path = prepare_store(ArraySource(h, sp), tmp_path_factory.mktemp("tpl") / "s", N)
    return path, h, sp


@pytest.fixture
def store(template, tmp_path):
    path, h, sp = template
    shutil.copytree(path, tmp_path / "s")
    return tmp_path / "s", h.copy(), sp


def _brushes(hf):
    ox, oy, _ = hf.origin
    return [
        Crater((ox + 40 * 160.0, oy + 64 * 160.0), 1200.0, 300.0),  # on a tile corner (64, 32)
        Raise((ox + 100 * 160.0, oy + 30 * 160.0), 2000.0, 150.0),
    ]


def _edited(h, sp, ctx):
    mem = HeightField(h.copy(), sp)
    with TerrainEditor(ctx, mem) as e:
        for b in _brushes(mem):
            e.apply(b)
    return mem


def _assert_store_holds(path, mem):
    """The reopened store equals the in-memory terrain: every level's tiles, bounds, the node arrays tiles read
    (both forms) and every tile's node block."""
    import zarr

    st = open_store(path)
    stored, ref = StorePyramid(st), TilePyramid(mem, N)
    for level in range(ref.max_level + 1):
        assert np.array_equal(stored._zmin[level], ref._zmin[level]) and np.array_equal(
            stored._zmax[level], ref._zmax[level]
        )
        assert np.allclose(stored._err[level], ref._err[level], rtol=1e-9, atol=1e-9)
        for key in ref.keys(level):
            assert np.array_equal(stored.tile(key).heights, ref.tile(key).heights), key
    got, want, combined = nodes_for(st, N), global_nodes(mem, N), global_nodes(mem, N, side_errors=False)
    raw = zarr.open_group(str(path), mode="r")
    for g, e in enumerate(want.effective):
        at = (slice(0, e.shape[0]), slice(0, e.shape[1]))
        for a, b in (
            (got.effective, want.effective),
            (got.zlo, want.zlo),
            (got.zhi, want.zhi),
            (got.sides, want.sides),
        ):
            assert np.array_equal(np.asarray(a[g][at]), b[g]), g
        assert np.array_equal(np.asarray(raw[f"nodes/combined/{g}"][at]), combined.effective[g]), g
    for level in range(ref.max_level + 1):
        for key in ref.keys(level):
            assert np.array_equal(
                tile_node_block(got, level, key.tx, key.ty, N)[0], tile_node_block(want, level, key.tx, key.ty, N)[0]
            ), key


def test_an_edit_written_through_reopens_and_draws_as_the_in_memory_edit(ctx, store):
    path, h, sp = store
    mem = _edited(h, sp, ctx)
    st = open_store(path)
    v = preset("flyover", mem, 6, 160, 90).view(2)
    live = Renderer(ctx, st, "hybrid", N, adapt=False)
    try:
        live.render(v)  # tiles resident before the edits
        with TerrainEditor(ctx, st, live) as editor:
            reports = [editor.apply(b) for b in _brushes(st)]
        assert all(r.store_files > 0 and r.ms["store"] > 0 for r in reports)
        assert verify_store(path) > 0
        _assert_store_holds(path, mem)
        again = open_store(path)
        for policy in ("raycast", "raster"):
            with Renderer(ctx, again, policy, N) as a, Renderer(ctx, mem, policy, N) as b:
                x, y = a.render(v), b.render(v)
            assert np.array_equal(x.colour, y.colour), policy
        with Renderer(ctx, again, "hybrid", N, adapt=False, cost_model=live.model) as fresh:
            np.testing.assert_allclose(live.render(v).distance, fresh.render(v).distance, rtol=1e-5)
    finally:
        live.release()


@pytest.mark.parametrize(
    ("where", "count", "state"),
    [
        ("_write", 3, "before"),  # while staging the chunks
        ("_move", 0, "before"),  # the commit marker's rename: nothing committed
        ("_move", 1, "after"),  # committed, no file in place yet
        ("_move", 5, "after"),  # committed, some files in place
    ],
)
def test_an_interrupted_write_through_leaves_the_store_before_or_after(ctx, store, monkeypatch, where, count, state):
    path, h, sp = store
    st = open_store(path)
    editor = TerrainEditor(ctx, st)
    real, calls = getattr(journal, where), []

    def crash(*args):
        calls.append(args)
        if len(calls) > count:
            raise OSError("simulated crash")
        return real(*args)

    brush = _brushes(st)[0]
    monkeypatch.setattr(journal, where, crash)
    with pytest.raises(OSError, match="simulated crash"):
        editor.apply(brush)
    monkeypatch.setattr(journal, where, real)
    after = editor.cpu.heights.copy()
    editor.release()
    assert verify_store(path) > 0  # the header's read recovers first
    assert not (path / journal.EDIT_DIR).exists()
    got = np.asarray(open_store(path).heights)
    assert np.array_equal(got, h if state == "before" else after)
    if state == "after":
        _assert_store_holds(path, HeightField(after, sp))


def test_the_write_follows_the_edit_not_the_store(ctx, tmp_path):
    src = puget(size=289)
    counts = []
    for size in (161, 289):  # levels 0..2 and 0..4 of tiles of 32
        h = np.ascontiguousarray(src.heights[:size, :size])
        path = prepare_store(ArraySource(h, (160.0, 160.0)), tmp_path / f"s{size}", N)
        files = len(open_store(path).store.store.files)
        with TerrainEditor(ctx, open_store(path)) as editor:
            rep = editor.apply(Raise((50 * 160.0, 40 * 160.0), 1500.0, 100.0))
            keys = editor.stored.last.keys
        win = rep.window
        counts.append(rep.store_files)
        assert rep.store_files == len(keys) + 2  # the chunks, the manifest and the header
        level0 = {tuple(int(i) for i in k.split("/")[-2:]) for k in keys if k.startswith("levels/0/")}
        assert level0 == {
            (a, b) for a in range(win.i0 // N, (win.i1 - 1) // N + 1) for b in range(win.j0 // N, (win.j1 - 1) // N + 1)
        }
        assert verify_store(path) > 0
    assert rep.store_files < files / 10, (rep.store_files, files)
    assert counts[1] <= counts[0] + 12, counts  # levels more: their bounds, a few chunks


def test_stores_an_edit_cannot_be_written_to_are_refused_by_name(ctx, store, tmp_path):
    import zarr

    from hybrid.tiles.periodic import open_periodic

    path, _, _ = store
    with pytest.raises(TerrabenchError, match="periodic extension"):
        TerrainEditor(ctx, open_periodic(path, 200))
    g = zarr.open_group(str(path), mode="r+")
    g.attrs.update({"node_blocks": False})
    with pytest.raises(TerrabenchError, match="node blocks"):
        TerrainEditor(ctx, open_store(path))


def test_an_edit_off_the_source_step_drops_the_stores_step(ctx, tmp_path):
    src = puget(size=97)
    path = prepare_store(
        ArraySource(np.ascontiguousarray(src.heights), (160.0, 160.0), src.source_step), tmp_path / "s", N
    )
    st = open_store(path)
    assert st.source_step is not None
    with TerrainEditor(ctx, st) as editor:
        editor.apply(Raise((40 * 160.0, 40 * 160.0), 900.0, 12.345))
    assert st.source_step is None and open_store(path).source_step is None
    assert verify_store(path) > 0
