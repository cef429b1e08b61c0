"""The triangle estimate's split tables (raster.split_tables) and their look-up (raster.estimate_loops:
kind_splits, the estimate's own) against brute-force counts:
exact for the errors rounded to their bin edge, and off the exact count only by nodes whose error lies within
half a bin of the threshold (bins split each octave in 32 equal steps: half a bin is at most 1/64 of the value),
or below the tables' floor 20 octaves under a tile's largest error."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from raster.estimate_loops import kind_splits
from raster.split_tables import BIN_SHIFT, TABLE_BINS, SplitTables, split_tables
from raster.tile_nodes import KINDS

HALF_BIN = 1 + 1 / 64  # the largest relative move of rounding to a bin edge


def rounded(e: np.ndarray) -> np.ndarray:
    """Errors (metres) rounded to the nearest bin edge as the tables do: float32 bits rounded at BIN_SHIFT."""
    bits = np.maximum(e, 0.0).astype(np.float32).view(np.int32).astype(np.int64)
    return (((bits + (1 << (BIN_SHIFT - 1))) >> BIN_SHIFT) << BIN_SHIFT).astype(np.int32).view(np.float32)


@st.composite
def tiles(draw):
    """Per kind (blocks, nodes) errors in metres: log-uniform over many octaves, with zeros, negatives, repeats
    (quantised heights give many equal errors) and values below the floor."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    nb = draw(st.sampled_from([1, 4, 16]))
    top = draw(st.floats(-3, 12))
    out = []
    for nodes in draw(st.tuples(st.integers(1, 40), st.integers(1, 40), st.integers(1, 40))):
        e = 2.0 ** rng.uniform(top - 30, top, (nb, nodes))
        e[rng.random(e.shape) < 0.15] = 0.0
        e[rng.random(e.shape) < 0.05] = -1.0
        e[rng.random(e.shape) < 0.2] = 2.0**top / 3  # a cluster of equal errors
        out.append(e)
    return out, rng


@settings(max_examples=80, deadline=None)
@given(tiles())
def test_split_tables_count_the_rounded_errors_above_a_threshold(tile):
    errors, rng = tile
    nb = errors[0].shape[0]
    base, table = split_tables(errors)
    tables = SplitTables(np.array([7, base]), np.zeros((2, len(KINDS), nb, TABLE_BINS), np.uint16))
    tables.tables[1] = table  # row 1 of two; row 0 counts nothing
    largest = max(float(e.max()) for e in errors)
    thr = np.concatenate(
        [
            2.0 ** rng.uniform(-40, 20, (60, 1, 1)) * np.ones((1, len(KINDS), nb)),
            np.array([0.0, np.inf, largest, largest / 3, 1e-30]).reshape(-1, 1, 1) * np.ones((1, len(KINDS), nb)),
        ]
    )
    rows = np.ones(len(thr), np.int64)
    got = kind_splits(tables.tables, tables.base, rows, thr)
    assert got.dtype == np.int64 and got.shape == thr.shape
    assert not kind_splits(tables.tables, tables.base, np.zeros(3, np.int64), thr[:3]).any()
    t32 = thr.astype(np.float32)
    top = rounded(np.array([largest])).view(np.int32)[0] >> BIN_SHIFT  # the largest error's bin
    floor = float(np.array([(top + 2 - TABLE_BINS) << BIN_SHIFT], np.int32).view(np.float32)[0]) if largest > 0 else 0.0
    for k, e in enumerate(errors):
        e = e[None]  # (1, blocks, nodes) against (T, blocks, 1)
        t = t32[:, k, :, None].astype(np.float64)
        r = rounded(e).astype(np.float64)
        positive = e > 0
        want_rounded = (positive & (np.maximum(r, floor) > t)).sum(axis=2)
        assert np.array_equal(got[:, k], want_rounded), k
        exact = (e > thr[:, k, :, None]).sum(axis=2)
        near = (positive & (((e >= t / HALF_BIN) & (e <= t * HALF_BIN)) | (e < floor))).sum(axis=2)
        assert np.all(np.abs(got[:, k] - exact) <= near), k
