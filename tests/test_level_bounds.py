"""A tile's per-level node extremes by the compiled loop equal numpy's reductions bit for bit, NaN included."""

import numpy as np
import pytest

from hybrid.tiles.store_blocks import block_offsets
from raster.selection import _level_bounds_numpy, level_bounds


@pytest.mark.parametrize("n", [2, 4, 16, 64])
def test_level_bounds_equal_numpy_reductions_bit_for_bit(n):
    rng = np.random.default_rng(n)
    offsets = block_offsets(n)
    data = rng.normal(size=(int(offsets[-1]), 4)).astype(np.float32)
    for nan_at in (None, int(offsets[0]) + n // 2 + 3):  # an inner node of level 0
        if nan_at is not None:
            data[nan_at, :3] = np.nan
        got, want = level_bounds(data, offsets, n, (2.0, 3.5)), _level_bounds_numpy(data, offsets, n, (2.0, 3.5))
        for a, b in zip(got, want):
            assert a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()
