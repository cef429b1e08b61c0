"""A virtual periodic extension of a store: its tiles are those of the source wrapped (checked against the
extension built in memory), its bounds and errors never below the exact ones, and it is labelled periodic."""

import numpy as np
import pytest
from test_store import ArraySource

from hybrid.errors import TerrabenchError
from hybrid.terrain.grid_sources import FractalSource
from hybrid.terrain.heightfield import HeightField
from hybrid.tiles.periodic import open_any_store, open_periodic
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.store import StorePyramid, prepare_store


def test_periodic_extension_wraps_the_source_and_bounds_hold(tmp_path):
    src = FractalSource(257, seed=3)
    prepare_store(src, tmp_path / "s", 32)
    ext = open_periodic(tmp_path / "s", 1025)
    h = src.read_rows(0, 257)
    wrapped = np.pad(np.tile(h[:-1, :-1], (4, 4)), ((0, 1), (0, 1)), mode="wrap")  # sample (i, j) -> (i, j) mod 256
    assert np.array_equal(np.asarray(ext.heights[:, :]), wrapped)
    assert ext.name.endswith("-periodic-1025") and ext.store.attrs["periodic"]["period_cells"] == 256
    stored, mem = StorePyramid(ext), TilePyramid(HeightField(wrapped, 10.0), 32)
    assert stored.max_level == mem.max_level == 5
    for level in range(mem.max_level + 1):
        for key in mem.keys(level):
            assert np.array_equal(stored.tile(key).heights, mem.tile(key).heights), key
        assert (stored._zmin[level] <= mem._zmin[level] + 1e-4).all()
        assert (stored._zmax[level] >= mem._zmax[level] - 1e-4).all()
        assert (stored._err[level] >= mem._err[level] - 1e-4).all()
    inside = np.s_[:7, :7]  # level-0 and -1 tiles off the seams: the source's own
    assert np.allclose(stored._err[1][:3, :3], mem._err[1][:3, :3]) and np.all(stored._err[0][inside] == 0)
    assert open_any_store(f"{tmp_path / 's'}@periodic1025").name == ext.name
    for bad in (1000, 257, 2**30):
        with pytest.raises(TerrabenchError, match="periodic size"):
            open_periodic(tmp_path / "s", bad)


def test_a_seamless_source_extends_without_seam_error(tmp_path):
    src = FractalSource(513, seed=2, period=512, feature_cells=256)  # the smallest period takes features of 256
    h = src.read_rows(0, 513)
    assert np.array_equal(h[:, 0], h[:, -1]) and np.array_equal(h[0], h[-1])  # seamless by construction
    prepare_store(src, tmp_path / "s", 64)
    ext, plain = StorePyramid(open_periodic(tmp_path / "s", 2049)), StorePyramid(tmp_path / "s")
    # tiles inside a period keep the source's errors exactly: no seam step to add
    for level in range(plain.max_level + 1):
        t = plain._err[level].shape[0]
        assert np.allclose(ext._err[level][:t, :t], plain._err[level]), level
    with pytest.raises(TerrabenchError, match="period must be a power of two"):
        FractalSource(1025, period=1000)


def _bounds_hold(ext, n):
    """The extension's pyramid against the in-memory pyramid of its whole grid: the same tiles and samples, bounds
    and errors never tighter than the exact ones."""
    stored, mem = StorePyramid(ext), TilePyramid(ext.load(), n)
    assert stored.max_level == mem.max_level
    for level in range(mem.max_level + 1):
        assert stored.tile_counts(level) == mem.tile_counts(level) == stored._err[level].shape, level
        for key in mem.keys(level):
            assert np.array_equal(stored.tile(key).heights, mem.tile(key).heights), key
        assert (stored._zmin[level] <= mem._zmin[level]).all() and (stored._zmax[level] >= mem._zmax[level]).all()
        assert (stored._err[level] >= mem._err[level] - 1e-6).all(), level


def test_seam_corner_tiles_take_in_the_source_corner_sample(tmp_path):
    h = FractalSource(129, seed=4).read_rows(0, 129)
    h[0, 0], h[0, 1] = h.min() - 500.0, h.max() + 500.0  # a pit at the corner, where four seams meet
    prepare_store(ArraySource(h, 10.0), tmp_path / "s", 16)
    _bounds_hold(open_periodic(tmp_path / "s", 257), 16)


@pytest.mark.parametrize("periods", [3, 5])
def test_an_extension_of_any_whole_number_of_periods_has_every_tile(tmp_path, periods):
    prepare_store(FractalSource(129, seed=1), tmp_path / "s", 32)
    ext = open_periodic(tmp_path / "s", 128 * periods + 1)
    _bounds_hold(ext, 32)
    assert StorePyramid(ext).tile_counts(StorePyramid(ext).max_level) == (1, 1)
