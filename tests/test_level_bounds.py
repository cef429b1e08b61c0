"""A tile's per-level node extremes by the compiled loop, turned into bounds rows as an upload does
(``raster.host_nodes``), equal numpy's reductions bit for bit, NaN included."""

import numpy as np
import pytest

from hybrid.tiles.store_blocks import block_offsets
from raster.bounds_loops import level_extremes
from raster.host_nodes import bounds_rows


def _level_bounds_numpy(data: np.ndarray, offsets: np.ndarray, n: int, spacing_xy: tuple[float, float]):
    """Per local level: largest effective error and the union of its own nodes' boxes, by numpy reductions level by
    level (the reference the compiled loop is tested against)."""
    levels = len(offsets) - 1
    sp = np.asarray(spacing_xy, dtype=np.float64)
    err, lo, hi = np.zeros(levels), np.zeros((levels, 3)), np.zeros((levels, 3))
    for m in range(levels):
        side = n >> (m + 1)
        own = data[offsets[m] : offsets[m + 1]].reshape(side + 2, side + 2, 4)[1:-1, 1:-1]
        grow = (2 << m) * sp
        err[m] = own[..., 0].max()
        lo[m] = (*(-grow), own[..., 1].min())
        hi[m] = (*(n * sp + grow), own[..., 2].max())
    return err, lo, hi


@pytest.mark.parametrize("n", [2, 4, 16, 64])
def test_level_bounds_equal_numpy_reductions_bit_for_bit(n):
    rng = np.random.default_rng(n)
    offsets = block_offsets(n)
    data = rng.normal(size=(int(offsets[-1]), 4)).astype(np.float32)
    for nan_at in (None, int(offsets[0]) + n // 2 + 3):  # an inner node of level 0
        if nan_at is not None:
            data[nan_at, :3] = np.nan
        got = bounds_rows(*level_extremes(data, np.asarray(offsets, np.int64), n), n, (2.0, 3.5))
        want = _level_bounds_numpy(data, offsets, n, (2.0, 3.5))
        for a, b in zip(got, want):
            assert a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()
