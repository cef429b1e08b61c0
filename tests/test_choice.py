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
    # a mixed frame's own overhead: mixing saves 4 ms here, so it mixes at 3.9 ms and stays pure at 4.1
    assert best_assignment(costs, {"a": 0.0, "b": 0.0}, mixed=3.9) == (["a", "b"], 5.9)
    assert best_assignment(costs, {"a": 0.0, "b": 0.0}, mixed=4.1) == (["a", "a"], 6.0)


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 5), st.integers(2, 3), st.integers(0, 2**32 - 1), st.sampled_from([0.0, 0.7, 2.5]))
def test_matches_brute_force(n_tiles, n_strategies, seed, mixed):
    rng = np.random.default_rng(seed)
    names = "abc"[:n_strategies]
    costs = {n: rng.uniform(0.0, 3.0, n_tiles) for n in names}
    overhead = {n: float(rng.uniform(0.0, 2.0)) for n in names}

    def frame(assign):
        used = set(assign)
        return sum(costs[c][i] for i, c in enumerate(assign)) + sum(overhead[c] for c in used) + mixed * (len(used) > 1)

    best = min(frame(assign) for assign in itertools.product(names, repeat=n_tiles))
    chosen, total = best_assignment(costs, overhead, mixed=mixed)
    assert np.isclose(total, best) and np.isclose(frame(chosen), best)


def test_hedged_choices_leave_the_base_only_beyond_the_model_error():
    from hybrid.cost.model import CostModel
    from hybrid.cost.planner import hedged_choices

    zero = {"const": 0.0, "triangles": 0.0, "visible_triangles": 0.0, "pixels": 0.0}
    m = CostModel(
        "t",
        {"raster": zero, "raycast": {"const": 0.0, "pixels": 0.0, "surface_pixels": 0.0, "pixel_steps": 0.0}},
        fit_error={"raster": 0.15, "raycast": 0.10},
        overhead={"raster": 0.0, "raycast": 0.0},
    )
    # ray casting is the cheaper pure frame (9 vs 10.5 ms): the base. Tile 0 is 17 % cheaper rasterized (inside
    # 0.15 + 0.10 of error: stays), tile 1 is 60 % cheaper (leaves), tile 2 is cheaper ray cast anyway
    pred = {"raster": np.array([2.5, 1.0, 7.0]), "raycast": np.array([3.0, 2.5, 3.5])}
    assert hedged_choices(pred, m) == ["raycast", "raster", "raycast"]
    pred["raster"][0] = 2.4 / 1.25  # 36 % cheaper: beyond the error, it leaves too
    assert hedged_choices(pred, m) == ["raster", "raster", "raycast"]
    # a tile that leaves by more than the error, but a frame that saves less than the base's 10 %: stays pure
    few = {"raster": np.array([2.5, 1.2, 7.0]), "raycast": np.array([3.0, 2.0, 3.5])}  # 7.7 against 8.5 ms
    assert hedged_choices(few, m) == ["raycast", "raycast", "raycast"]
    few["raster"][1] = 1.0  # 7.5 against 8.5: beyond 10 %, it mixes
    assert hedged_choices(few, m) == ["raycast", "raster", "raycast"]
    m.mix_error = 0.2  # unless mixed frames were predicted worse than that
    assert hedged_choices(few, m) == ["raycast", "raycast", "raycast"]
    m.mix_error = 0.0
    # per-tile errors, where the model has them, set the tile's hedge: 1.0 against 2.0 is inside 0.6 + 0.5
    m.tile_error = {"raster": 0.6, "raycast": 0.5}
    assert hedged_choices(few, m) == ["raycast", "raycast", "raycast"]
    m.tile_error = {}
    # without a measured error the plain cheapest assignment
    m.fit_error = {}
    assert hedged_choices(pred, m) == best_assignment(pred, m.overhead)[0] == ["raster", "raster", "raycast"]
    # a mixed frame's own overhead counts against the mix: it saves 2.58 ms against all ray cast (6.42 vs 9.0)
    m.mix_overhead = 2.5
    assert hedged_choices(pred, m) == ["raster", "raster", "raycast"]
    m.mix_overhead = 2.7
    assert hedged_choices(pred, m) == ["raycast", "raycast", "raycast"]


def test_hedged_picks_shortcut_agrees_with_pricing_every_subset():
    """A frame whose tiles all stay with the base is recognised without pricing the subsets; on 3000 random small
    frames (costs, overheads, errors from a few values, so that ties and near-ties are common, half of them with
    one strategy cheapest everywhere) the picks are those of the full computation (the shortcut turned off)."""
    import hybrid.cost.planner as planner
    from hybrid.cost.model import CostModel

    rng = np.random.default_rng(7)
    original, taken = planner._pure_base_wins, 0
    for _ in range(3000):
        s, b = int(rng.integers(2, 4)), int(rng.integers(0, 7))
        names = ["raster", "raycast", "raster_gs"][:s]
        table = rng.choice([1.0, 1.05, 2.0, 5.0], size=(s, b))
        if rng.random() < 0.5:
            table[0] = table.min(axis=0)
        errs = {n: float(rng.choice([0.0, 0.1])) for n in names}
        model = CostModel(
            "test",
            {"raster": {"const": 0.0}, "raycast": {"const": 0.0}, **({"raster_gs": {"const": 0.0}} if s > 2 else {})},
            fit_error=dict(errs),
            tile_error=dict(errs),
            overhead={n: float(rng.choice([0.0, 1.0, 3.0])) for n in names},
            mix_overhead=float(rng.choice([0.0, 0.5])),
            mix_error=float(rng.choice([0.0, 0.05])),
        )
        calls = []
        planner._pure_base_wins = lambda *a, calls=calls: calls.append(original(*a)) or calls[-1]
        try:
            fast = planner.hedged_picks(table, names, model).tolist()
            planner._pure_base_wins = lambda *a: False
            full = planner.hedged_picks(table, names, model).tolist()
        finally:
            planner._pure_base_wins = original
        assert fast == full, (table, model.overhead, model.mix_overhead)
        taken += any(calls)
    assert 500 < taken < 2500  # the shortcut is taken often, and often not


def test_hedged_picks_shortcut_needs_the_base_overhead_least():
    """Ray casting is cheapest on every tile but carries the largest overhead; raster and raster_gs tie with it on
    half the tiles each and cost no overhead: their mix is the cheapest frame, which the shortcut must not hide."""
    from hybrid.cost.model import CostModel
    from hybrid.cost.planner import hedged_picks

    table = np.array([[1.0, 1.0, 9.0, 9.0], [1.0, 1.0, 1.0, 1.0], [9.0, 9.0, 1.0, 1.0]])
    model = CostModel(
        "test",
        {"raster": {"const": 0.0}, "raycast": {"const": 0.0}, "raster_gs": {"const": 0.0}},
        overhead={"raster": 0.0, "raycast": 5.0, "raster_gs": 0.0},
    )
    assert hedged_picks(table, ["raster", "raycast", "raster_gs"], model).tolist() == [0, 0, 2, 2]


def test_compiled_choice_equals_the_numpy_forms():
    """The plan's compiled pass (terms, predictions, hedged picks) against the numpy forms it replaces, on 2000 random
    frames of features (some triangles unknown) and models whose costs, overheads and errors come from a few
    values, so that ties and near-ties are common. The picks are compared on the compiled table, equal to the numpy
    one within rounding, which may break an exact tie either way."""
    from hybrid.cost.model import TERMS, CostModel, all_term_values
    from hybrid.cost.planner import compiled_choice, hedged_picks

    rng = np.random.default_rng(3)
    mismatches = 0
    for trial in range(2000):
        b = int(rng.integers(1, 8))  # numpy sums fewer than 8 in order, as the loops do
        columns = {
            "pixels": rng.choice([0.0, 100.0, 2500.0], b),
            "triangles": rng.choice([0.0, 500.0, 4000.0, np.nan] if trial % 3 == 0 else [0.0, 500.0, 4000.0], b),
            "visible": rng.choice([0.2, 1.0], b),
            "surface_pixels": rng.choice([0.0, 80.0, 2000.0], b),
            "slab_cells": rng.choice([0.0, 3.0, 40.0], b),
        }
        names = ["raster", "raycast", "raster_gs"][: int(rng.integers(2, 4))]
        coefficients = {s: {t: float(rng.choice([0.0, 1e-4, 1e-3])) for t in TERMS[s]} for s in names}
        for s in names:
            coefficients[s]["const"] = float(rng.choice([0.01, 0.2]))  # every strategy present
        errs = {n: float(rng.choice([0.0, 0.1, 0.3])) for n in names}
        model = CostModel(
            "test",
            coefficients,
            fit_error=dict(errs),
            tile_error={n: float(rng.choice([0.0, 0.2])) for n in names},
            overhead={n: float(rng.choice([0.0, 0.5, 3.0])) for n in names},
            mix_overhead=float(rng.choice([0.0, 0.5])),
            mix_error=float(rng.choice([0.0, 0.05])),
        )
        terms, table, picks = compiled_choice(model, columns)
        want_terms = all_term_values(columns)
        want_table = model.predict_terms(want_terms, unknown=np.inf)
        np.testing.assert_allclose(terms, want_terms, rtol=1e-12)
        np.testing.assert_allclose(table, want_table, rtol=1e-12)
        assert picks is not None
        mismatches += picks.tolist() != hedged_picks(table, model.candidates, model).tolist()  # ties: same rounding
    assert mismatches == 0
