"""Streaming after a camera jump (experiments.stream_jump): per frame the share of tiles drawn at their wanted
level, counted, never timed; with the loader settled between frames and one job a frame, every frame draws one
more tile at its wanted level until all are."""

import pandas as pd
import pytest

from experiments.scaling_report import jump_sentences
from experiments.stream_jump import frames_to, jump_frames, jump_summary, jump_table, run_jumps
from hybrid.terrain.grid_sources import FractalSource
from hybrid.tiles.store import prepare_store

SIZE = (160, 90)


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    return prepare_store(FractalSource(257, seed=0), tmp_path_factory.mktemp("jump") / "f257", 32)


def _rows(shares):
    return pd.DataFrame(
        {"frame": range(1, len(shares) + 1), "share": shares, "uploads": 1, "upload_ms": 0.0, "wall_ms": 1.0}
    )


def test_frames_to_is_the_first_frame_from_which_the_share_stays_reached():
    assert frames_to(_rows([0.1, 0.96, 0.9, 0.95, 1.0])) == 4
    assert frames_to(_rows([0.95, 1.0])) == 1
    assert frames_to(_rows([0.1, 0.5])) is None
    assert frames_to(_rows([0.1, 0.96, 0.5])) is None
    assert jump_summary(_rows([0.1, 0.96, 0.97]))["frames_to_share"] == 2


@pytest.mark.parametrize("method", ["raycast", "raster"])
def test_after_a_jump_one_job_a_frame_brings_one_more_tile_to_its_level(ctx, store, method):
    rows = jump_frames(ctx, store, method, frames=40, size=SIZE, upload_budget_ms=0.0, settle=True)
    tiles = int(rows["tiles"].iloc[0])
    assert (rows["tiles"] == tiles).all() and tiles > 4
    before = tiles - int(rows["at_wanted"].iloc[0]) + 1  # missing at the jump (frame 1 runs one job)
    assert (rows["uploads"].iloc[:before] == 1).all()
    want = [min(tiles, tiles - before + k) for k in range(1, len(rows) + 1)]
    assert list(rows["at_wanted"]) == want
    assert frames_to(rows, 1.0) == before


def test_the_scaling_report_says_how_many_jumps_met_the_target(ctx, store):
    rows = run_jumps(ctx, [store], ["raycast"], frames=3, size=SIZE, upload_budget_ms=0.0)
    table = jump_table(rows)
    assert list(table["method"]) == ["raycast"] and len(rows) == 3
    (line,) = jump_sentences(table)
    assert "target met in 0 of 1" in line and "not reached" in line


def test_after_a_jump_the_hybrid_builds_its_estimate_in_the_loader_and_uploads_many_a_frame(ctx, store, monkeypatch):
    import threading

    from raster.estimate import TileletTriangleEstimator

    threads = []
    real = TileletTriangleEstimator._block_nodes

    def spy(self, source, key):
        threads.append(threading.current_thread().name)
        return real(self, source, key)

    monkeypatch.setattr(TileletTriangleEstimator, "_block_nodes", spy)
    rows = jump_frames(ctx, store, "hybrid", frames=6, size=SIZE, upload_budget_ms=1e3, settle=True)
    assert threads and set(threads) == {"terrabench-tile-loader"}  # no estimate's build inside a frame
    assert rows["uploads"].iloc[0] > 1  # every missing tile's job fits the budget: not one job a frame
    assert rows["share"].iloc[-1] == 1.0


def test_the_view_before_the_jump_is_settled_with_its_seam_cuts_done(ctx, tmp_path):
    from test_periodic_nodes import _rough
    from test_periodic_streaming import _seam_view

    from experiments.stream_jump import _settled
    from hybrid.renderer import Renderer
    from hybrid.tiles.periodic import open_periodic
    from hybrid.tiles.store import StorePyramid

    prepare_store(_rough(seed=4), tmp_path / "s", 16)
    ext = open_periodic(tmp_path / "s", 385)
    pyramid, v = StorePyramid(ext), _seam_view(ext)
    with Renderer(ctx, ext, "raster", 16, pyramid=pyramid, upload_budget_ms=1e9, adapt=False) as r:
        assert r.render(v, 2.0, read=False).stats.fallback_tiles > 0  # near-seam tiles wait for their cuts
        _settled(r, pyramid, v, 2.0)
        assert r.render(v, 2.0, read=False).stats.fallback_tiles == 0
    pyramid.close()
