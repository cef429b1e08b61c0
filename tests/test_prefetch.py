"""Prefetch along the camera's motion (hybrid.streaming.ahead_keys): a store's loader reads the samples of the
tiles one tile ahead of the frame's, into the host cache only, counted, never timed."""

from dataclasses import replace

import numpy as np
import pytest

from hybrid.renderer import Renderer
from hybrid.streaming import ahead_keys
from hybrid.terrain.grid_sources import FractalSource
from hybrid.terrain.stored import open_store
from hybrid.tiles.pyramid import TileKey
from hybrid.tiles.store import StorePyramid, prepare_store


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    return prepare_store(FractalSource(257, seed=0), tmp_path_factory.mktemp("prefetch") / "f257", 32)


class _Plan:
    def __init__(self, key):
        self.key = key


def test_ahead_keys_step_each_tile_along_the_motion_within_the_level(store):
    pyramid = StorePyramid(open_store(store))
    plans = [_Plan(TileKey(0, 3, 2)), _Plan(TileKey(0, 4, 2)), _Plan(TileKey(0, 7, 5)), _Plan(TileKey(1, 1, 1))]
    assert ahead_keys(pyramid, plans, np.zeros(3)) == []
    east = set(ahead_keys(pyramid, plans, np.array([10.0, 1.0, 0.0])))
    assert east == {TileKey(0, 5, 2), TileKey(1, 2, 1)}  # (0, 4, 2) is the frame's own; (0, 8, 5) lies off the grid
    north_west = set(ahead_keys(pyramid, plans, np.array([-5.0, 5.0, 0.0])))
    assert north_west == {TileKey(0, 2, 3), TileKey(0, 3, 3), TileKey(0, 6, 6), TileKey(1, 0, 2)}
    pyramid.close()


def test_a_moving_camera_has_the_loader_read_the_tiles_ahead_and_upload_nothing_more(ctx, store):
    from hybrid.camera.flight import preset

    terrain = open_store(store)
    view = preset("flyover", terrain, 4, 160, 90).view(1)
    pyramid = StorePyramid(terrain)
    with Renderer(ctx, terrain, "raycast", 32, pyramid=pyramid, upload_budget_ms=1e6) as r:
        r.render(view, read=False)
        pyramid.idle(60)
        still = r.render(view, read=False)  # no motion: nothing read ahead
        pyramid.idle(60)
        ahead_still = ahead_keys(pyramid, still.plans, np.array([40.0, 0.0, 0.0]))
        assert ahead_still and not pyramid.cached_keys(ahead_still)
        moved = replace(view, eye=view.eye + [40.0, 0.0, 0.0], target=view.target + [40.0, 0.0, 0.0])
        res = r.render(moved, read=False)
        pyramid.idle(60)
        ahead = ahead_keys(pyramid, res.plans, np.array([40.0, 0.0, 0.0]))
        assert ahead and pyramid.cached_keys(ahead) == set(ahead)
        assert res.stats.uploads <= len({p.key for p in res.plans})  # uploads only the frame's own tiles
    pyramid.close()
