"""The cheapest assignment of tiles to strategies: hand cases and a brute force over every assignment."""
import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hybrid.cost.choice import best_assignment


def test_hand_cases():
    costs = {"a": np.array([1.0, 5.0]), "b": np.array([5.0, 1.0])}
    assert best_assignment(costs, {"a": 0.0, "b": 0.0}) == (["a", "b"], 2.0)
    # b's overhead outweighs what it saves: every tile goes to a
    assert best_assignment(costs, {"a": 0.0, "b": 10.0}) == (["a", "a"], 6.0)
    # a measured pure frame replaces the sum of its tiles
    assert best_assignment(costs, {"a": 0.0, "b": 10.0}, {"a": 1.5}) == (["a", "a"], 1.5)
    # a third strategy used for the one tile where it saves more than its overhead
    three = {**costs, "c": np.array([0.1, 4.0])}
    assert best_assignment(three, {"a": 0.0, "b": 0.0, "c": 0.5}) == (["c", "b"], 1.6)
    assert best_assignment(three, {"a": 0.0, "b": 0.0, "c": 1.0}) == (["a", "b"], 2.0)
    # ties go to the earlier strategy; no tiles at all is a frame of nothing
    assert best_assignment({"a": np.array([1.0]), "b": np.array([1.0])}, {}) == (["a"], 1.0)
    assert best_assignment({"a": np.array([]), "b": np.array([])}, {"a": 0.3, "b": 0.2}) == ([], 0.2)


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 5), st.integers(2, 3), st.integers(0, 2**32 - 1))
def test_matches_brute_force(n_tiles, n_strategies, seed):
    rng = np.random.default_rng(seed)
    names = "abc"[:n_strategies]
    costs = {n: rng.uniform(0.0, 3.0, n_tiles) for n in names}
    overhead = {n: float(rng.uniform(0.0, 2.0)) for n in names}
    best = min(sum(costs[c][i] for i, c in enumerate(assign)) + sum(overhead[c] for c in set(assign))
               for assign in itertools.product(names, repeat=n_tiles))
    chosen, total = best_assignment(costs, overhead)
    recomputed = sum(costs[c][i] for i, c in enumerate(chosen)) + sum(overhead[c] for c in set(chosen))
    assert np.isclose(total, best) and np.isclose(recomputed, best)
