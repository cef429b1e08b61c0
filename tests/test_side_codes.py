"""Side-error codes (hybrid.tiles.sidecodes.side_codes) as the GPU and the triangle estimate read them back: never below the
measured side error (a midpoint is never dropped that the bound needs), at most one code step (2^(1/8)) above it
inside the coded range, 2^-7 of the parent's error at the floor, and 'always keep' above the range, without a
parent or with a parent error of 0."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hybrid.tiles.sidecodes import SIDE_BIAS, SIDE_STEPS, decoded_sides, side_codes

STEP = 2.0 ** (1.0 / SIDE_STEPS)


def _round_trip(sides, effective, parent):
    w = side_codes(sides, effective, parent)
    assert w.dtype == np.float32 and np.all(w >= 1) and np.all(w <= 2**24) and np.all(w == np.round(w))
    return decoded_sides(w, parent)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31), st.floats(1e-3, 1e4))
def test_decoded_sides_bound_the_measured_ones(seed, scale):
    rng = np.random.default_rng(seed)
    parent = (rng.random((2, 2)) * scale).astype(np.float32)
    parent[0, 0] = 0.0  # a parent fan that is exact
    P = np.repeat(np.repeat(parent.astype(np.float64), 2, 0), 2, 1)
    effective = (rng.random((4, 4)) * P * 0.9).astype(np.float32)  # a child's E is below its parent's
    sides = P[None] * np.exp2(rng.uniform(-12, 3, (4, 4, 4)))  # from far below to above the coded range
    sides[:, 3, 3] = 0.0  # an exact side
    got = _round_trip(sides, effective, parent)
    S = np.maximum(sides, effective[None])
    assert np.all(got >= S)  # never below: conservative
    coded = (P[None] > 0) & (S > P[None] * 2.0 ** (-SIDE_BIAS / SIDE_STEPS)) & (S <= P[None] * 2.0 ** (6 / SIDE_STEPS))
    assert np.all(got[coded] <= S[coded] * STEP * (1 + 1e-6))  # one step at most
    floor = (P[None] > 0) & (S <= P[None] * 2.0 ** (-SIDE_BIAS / SIDE_STEPS))
    assert np.allclose(got[floor], (P[None] * 2.0 ** (-SIDE_BIAS / SIDE_STEPS) * np.ones_like(S))[floor])
    assert np.all(np.isinf(got[(P[None] == 0) & (S > 0)]))  # exact parent, inexact side: always kept
    assert np.all(got[(P[None] == 0) & (S == 0)] == 0)  # both exact: always dropped


def test_nodes_without_a_parent_always_keep_their_midpoints():
    got = _round_trip(np.zeros((4, 1, 1)), np.zeros((1, 1), np.float32), None)
    assert np.all(np.isinf(got))
