"""Online adaptation of the cost model: refits move predictions toward measured times, exploration stays within
its budget and stops once predictions hold, a frozen hybrid chooses the same every run, learned models round-trip."""

import copy
import json
import warnings

import numpy as np
import pytest
from cost_helpers import columns, true_model

from hybrid.cost.model import (
    ONLINE_FIT_VERSION,
    TERMS,
    all_term_values,
    load_cost_model,
    read_costs_file,
    save_cost_model,
)
from hybrid.cost.online import AdaptOptions, Exploration, OnlineModel
from hybrid.cost.online_fit import fit_rows
from hybrid.errors import TerrabenchError

TRUE = true_model(overhead={"raster": 2.0, "raster_gs": 3.0, "raycast": 1.5}, mix_overhead=0.8)


def true_passes(cols, picks, rng, noise=0.03):
    """Each strategy's pass ms under TRUE (its overhead and its tiles), with multiplicative noise."""
    table = TRUE.predict_table(cols)
    names = TRUE.candidates
    out = {}
    for i, s in enumerate(names):
        sel = picks == s
        if sel.any():
            out[s] = (TRUE.overhead[s] + float(table[i, sel].sum())) * float(1 + noise * rng.standard_normal())
    return out


def scaled(model, strategy, factor):
    """A copy of the model with one strategy's coefficients and overhead multiplied by factor."""
    m = copy.deepcopy(model)
    m.coefficients = {**m.coefficients, strategy: {k: v * factor for k, v in m.coefficients[strategy].items()}}
    m.overhead = {**m.overhead, strategy: m.overhead[strategy] * factor}
    return m


def run_frames(online, rng, frames, explore=True):
    """Frames of 8-30 tiles chosen by the online model's cheapest prediction per tile, drawn 'by' TRUE."""
    errors = []
    for _ in range(frames):
        cols = columns(rng, int(rng.integers(8, 31)))
        names = online.model.candidates
        table = online.model.predict_table(cols)
        picks = table.argmin(axis=0)
        explored = online.explore(table, picks, names) if explore else None
        chosen = np.array([names[i] for i in picks])
        passes = true_passes(cols, chosen, rng)
        predicted = sum(online.model.overhead[s] + float(table[names.index(s), chosen == s].sum()) for s in passes)
        frame = sum(passes.values()) + (TRUE.mix_overhead if len(passes) > 1 else 0.0)
        errors.append(abs(predicted - sum(passes.values())) / sum(passes.values()))
        online.observe(cols, chosen.tolist(), passes, frame, explored)
    return np.array(errors)


def test_fit_rows_recovers_coefficients_from_a_wrong_prior():
    rng = np.random.default_rng(1)
    theta = np.r_[TRUE.overhead["raycast"], [TRUE.coefficients["raycast"][t] for t in TERMS["raycast"]]]
    X = np.c_[
        np.ones(48), np.array([all_term_values(columns(rng, 20))[:, [0, 3, 4, 5]].sum(axis=0) for _ in range(48)])
    ]
    y = X @ theta * (1 + 0.01 * rng.standard_normal(48))
    fitted = fit_rows(X, y, theta / 5, prior_weight=2.0)
    assert np.all(fitted >= 0)
    rel = np.abs(X @ fitted - y) / y
    assert np.median(rel) < 0.02  # the prior was 5x off: 80 % error before the fit
    assert np.median(np.abs(X @ (theta / 5) - y) / y) > 0.7


def test_fit_rows_keeps_the_prior_shape_from_passes_of_a_few_explored_tiles():
    rng = np.random.default_rng(7)
    theta = np.array([2.0, 0.3, 1e-4])  # overhead, per tile, per pixel
    X = np.c_[np.ones(40), rng.integers(1, 3, 40), rng.uniform(1e3, 2e4, 40)]
    y = (X @ np.array([0.5, 1.5, 1e-4])) * (1 + 0.05 * rng.standard_normal(40))  # another split, same level
    fitted = fit_rows(X, y, theta, prior_weight=2.0, shape_rows=12, few_tiles=2)
    assert np.isclose(fitted[1] / theta[1], fitted[2] / theta[2])  # the tiles keep the prior's split
    assert 0.8 < np.median((X @ fitted) / y) < 1.25
    X2 = np.r_[X, [[1.0, 20.0, 3e5]]]  # one pass of many tiles, 3x its prediction, sets the tiles' level
    y2 = np.r_[y, 3.0 * (X2[-1] @ theta)]
    fitted = fit_rows(X2, y2, theta, prior_weight=2.0, shape_rows=12, few_tiles=2)
    assert 0.8 < (X2[-1] @ fitted) / y2[-1] < 1.25  # a frame drawn whole is priced by it, not by the 40 small
    X[:, 1] = rng.integers(5, 30, 40)  # passes of many tiles: the split is learnt
    y = (X @ np.array([0.5, 1.5, 1e-4])) * (1 + 0.01 * rng.standard_normal(40))
    fitted = fit_rows(X, y, theta, prior_weight=2.0, shape_rows=12, few_tiles=2)
    assert fitted[1] / fitted[0] > 2 * theta[1] / theta[0]


def test_prior_share_damps_a_split_the_rows_barely_tell():
    rng = np.random.default_rng(8)
    theta = np.array([1.0, 0.25, 1e-4])
    X = np.c_[np.ones(48), rng.integers(11, 14, 48), rng.uniform(1e4, 2e4, 48)]  # tile counts nearly constant
    y = (X @ theta) * (1 + 0.15 * rng.standard_normal(48))  # noisy passes, same model
    free = fit_rows(X, y, theta, prior_weight=2.0)
    damped = fit_rows(X, y, theta, prior_weight=2.0, prior_share=0.5)
    assert abs(damped[0] - theta[0]) < abs(free[0] - theta[0])
    assert abs(damped[0] - theta[0]) < 0.5 * theta[0]


def test_a_strategy_that_could_not_pay_is_not_explored_once_its_level_is_known():
    rng = np.random.default_rng(9)
    online = OnlineModel(TRUE, AdaptOptions(explore_share=0.05, hold_error=0.0))  # predictions never 'hold'
    online.credit = 1e9
    cols = columns(rng, 20)
    names = TRUE.candidates
    table = TRUE.predict_table(cols)
    g = names.index("raster_gs")
    hopeless = table.copy()
    hopeless[g] = 10 * table.min(axis=0) + 10.0  # 10x the best of every tile
    picks = np.delete(hopeless, g, axis=0).argmin(axis=0)
    picks = np.where(picks >= g, picks + 1, picks)
    assert online.explore(hopeless, picks.copy(), names) is not None  # level unknown yet: it might pay
    for _ in range(AdaptOptions().hold_rows):
        online.rows["raster_gs"].add(np.ones(1 + len(TERMS["raster_gs"])), 5.0)
    assert all(online.explore(hopeless, picks.copy(), names) is None for _ in range(10))
    cheap = table.copy()
    cheap[g] = 0.2 * table.min(axis=0)  # a fifth of the best: worth a look
    assert any(online.explore(cheap, picks.copy(), names) is not None for _ in range(10))


def test_strategies_not_drawn_follow_the_machines_level():
    rng = np.random.default_rng(12)
    slow = copy.deepcopy(TRUE)  # the machine draws everything at half the model's speed
    for st in slow.candidates:
        slow.coefficients = {**slow.coefficients, st: {k: v / 2 for k, v in slow.coefficients[st].items()}}
        slow.overhead = {**slow.overhead, st: slow.overhead[st] / 2}
    online = OnlineModel(slow, AdaptOptions(explore_share=0.0))
    run_frames(online, rng, 30, explore=False)
    m = online.model
    drawn = {s for s in m.candidates if len(online.rows[s])}
    assert drawn and drawn != set(m.candidates)  # some strategy was never drawn
    assert online.machine_scale() == pytest.approx(2.0, rel=0.1)
    cols = columns(rng, 20)
    for s in set(m.candidates) - drawn:  # predicted at the machine's level all the same
        t = TRUE.predict_table(cols)[TRUE.candidates.index(s)].sum() + TRUE.overhead[s]
        p = m.predict_table(cols)[m.candidates.index(s)].sum() + m.overhead[s]
        assert abs(p - t) / t < 0.1, s


def test_fit_rows_drops_an_outlier():
    rng = np.random.default_rng(2)
    theta = np.array([1.0, 0.2, 1e-4])
    X = np.c_[np.ones(30), rng.uniform(5, 30, 30), rng.uniform(1e3, 5e4, 30)]
    y = X @ theta
    y[3] *= 8  # one frame stalled
    fitted = fit_rows(X, y, theta * 2, prior_weight=1.0)
    ok = np.arange(30) != 3
    assert np.median(np.abs(X[ok] @ fitted - y[ok]) / y[ok]) < 0.02


@pytest.mark.parametrize("wrong", ["raycast", "raster"])
def test_adaptation_moves_predictions_toward_measured(wrong):
    rng = np.random.default_rng(3)
    online = OnlineModel(scaled(TRUE, wrong, 0.2))
    errors = run_frames(online, rng, 60)
    assert errors[0] > 0.5  # the wrong strategy is chosen and mispredicted
    assert np.median(errors[-20:]) < 0.08
    m = online.model
    for s in m.candidates:  # every candidate learned, the unused ones by exploration
        cols = columns(rng, 20)
        t = TRUE.predict_table(cols)[TRUE.candidates.index(s)].sum() + TRUE.overhead[s]
        p = m.predict_table(cols)[m.candidates.index(s)].sum() + m.overhead[s]
        assert abs(p - t) / t < 0.2, s
    assert m.adapted_frames == 60


def test_exploration_stays_within_its_budget_and_stops_once_predictions_hold():
    rng = np.random.default_rng(4)
    online = OnlineModel(scaled(TRUE, "raster_gs", 3.0), AdaptOptions(explore_share=0.05))
    run_frames(online, rng, 200)
    st = online.stats
    assert st.explored_frames > 0
    assert st.explore_share <= 0.05 + 1e-9
    assert online.settled
    before = st.explored_frames
    run_frames(online, rng, 40)
    assert online.stats.explored_frames == before  # settled: no more exploration


def test_no_exploration_without_budget():
    rng = np.random.default_rng(5)
    online = OnlineModel(TRUE, AdaptOptions(explore_share=0.0))
    run_frames(online, rng, 30)
    assert online.stats.explored_frames == 0


def test_bad_adapt_options_are_refused():
    with pytest.raises(TerrabenchError, match="explore_share"):
        AdaptOptions(explore_share=float("nan"))
    with pytest.raises(TerrabenchError, match="window"):
        AdaptOptions(window=2)


def test_learned_model_round_trips_through_the_costs_file(tmp_path):
    rng = np.random.default_rng(6)
    online = OnlineModel(scaled(TRUE, "raycast", 0.5))
    run_frames(online, rng, 30)
    path = tmp_path / "costs.json"
    save_cost_model(online.model, path)
    back = load_cost_model("test", path)
    assert back.adapted_frames == 30
    for s in back.candidates:
        assert back.coefficients[s] == pytest.approx(online.model.coefficients[s])
        assert back.overhead[s] == pytest.approx(online.model.overhead[s])


def test_a_model_learned_by_an_earlier_online_fit_is_passed_over(tmp_path):
    rng = np.random.default_rng(6)
    online = OnlineModel(scaled(TRUE, "raycast", 0.5))
    run_frames(online, rng, 12)
    path = tmp_path / "costs.json"
    old = copy.deepcopy(online.model)
    old.renderer, old.online_fit = "llvmpipe", ONLINE_FIT_VERSION - 1
    save_cost_model(old, path)
    with pytest.warns(UserWarning, match="earlier version of the online fit"):
        got = load_cost_model("llvmpipe", path)
    assert got.adapted_frames == 0 and got.source.startswith("shipped default")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # said once a process, not at every renderer of a run
        assert load_cost_model("llvmpipe", path).adapted_frames == 0
    old.online_fit = ONLINE_FIT_VERSION  # learned by this version: used
    save_cost_model(old, path)
    assert load_cost_model("llvmpipe", path).adapted_frames == 12


@pytest.mark.parametrize("text", ["{not json", "[1, 2]", '{"llvmpipe": 3}', "\u00ff\u00fe"])
def test_corrupt_or_foreign_costs_file_is_refused_by_name(tmp_path, text):
    path = tmp_path / "costs.json"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(TerrabenchError, match=r"costs\.json"):
        read_costs_file(path)
    with pytest.raises(TerrabenchError, match=r"costs\.json"):
        load_cost_model("llvmpipe", path)


def test_costs_file_model_of_wrong_shape_is_refused_by_name(tmp_path):
    path = tmp_path / "costs.json"
    path.write_text(json.dumps({"llvmpipe": {"renderer": "llvmpipe", "raster": []}}))
    with pytest.raises(TerrabenchError, match="malformed cost model"):
        load_cost_model("llvmpipe", path)


def test_mixed_frames_over_their_predictions_raise_the_share_a_mix_must_save():
    rng = np.random.default_rng(13)
    online = OnlineModel(TRUE, AdaptOptions(window=12))
    start = TRUE.mix_error
    names = TRUE.candidates

    def frame(mixed: bool, over: float, explored=None):
        cols = columns(rng, 10)
        chosen = np.array([names[0]] * 10, dtype=object)
        if mixed:
            chosen[:4] = "raycast"
        passes = true_passes(cols, chosen, rng, noise=0.0)
        predicted = sum(passes.values())
        online.observe(cols, chosen.tolist(), passes, predicted * over, explored, predicted)

    frame(True, 1.0)  # first passes of each strategy: one-off costs, not checked
    for _ in range(4):
        frame(False, 1.1)
    for _ in range(2):
        frame(True, 1.43)
    assert online.model.mix_error == start  # two mixed frames say too little
    frame(True, 1.43, explored=Exploration("raycast", np.arange(4), 1.0))
    assert online.model.mix_error == start  # an explored frame is not the hybrid's choice: not checked
    frame(True, 1.43)
    assert online.model.mix_error == pytest.approx(0.3, abs=1e-9)  # 1.43 / 1.1 - 1
    for _ in range(12):
        frame(False, 1.1)
    assert online.model.mix_error == start  # the mixed frames aged out of the window: a mix is tried again


def test_a_strategys_first_pass_is_not_charged_to_the_exploration_budget():
    rng = np.random.default_rng(14)
    online = OnlineModel(TRUE)
    names = TRUE.candidates
    cols = columns(rng, 10)
    chosen = np.array(["raster"] * 10, dtype=object)
    first = true_passes(cols, chosen, rng)
    online.observe(cols, chosen.tolist(), first, sum(first.values()))  # raster's own first pass
    online.credit = 5.0
    chosen[:2] = "raycast"
    passes = {**true_passes(cols, chosen, rng), "raycast": 2000.0}  # its shaders compiled in this pass
    online.observe(cols, chosen.tolist(), passes, 2020.0, Exploration("raycast", np.arange(2), 1.0))
    assert online.credit > 5.0 and online.stats.explore_ms == 0.0  # the compile is not exploration's cost
    assert online.explore(TRUE.predict_table(cols), np.zeros(10, int), names) is not None  # still affordable
    passes["raycast"] = 4.0
    online.observe(cols, chosen.tolist(), passes, sum(passes.values()), Exploration("raycast", np.arange(2), 1.0))
    assert online.stats.explore_ms == pytest.approx(3.0)  # a later pass is charged what it cost beyond the base


def test_a_learned_model_never_overwrites_the_calibrated_one(tmp_path):
    rng = np.random.default_rng(15)
    path = tmp_path / "costs.json"
    calibrated = scaled(TRUE, "raycast", 2.0)
    save_cost_model(calibrated, path)
    online = OnlineModel(calibrated)
    run_frames(online, rng, 10)
    save_cost_model(online.model, path)
    data = read_costs_file(path)
    assert (
        data["test"]["coefficients"]["raycast"] == calibrated.coefficients["raycast"]
    )  # the calibration kept beside the learned model
    assert load_cost_model("test", path).adapted_frames == 10  # the learned one is used
    old = copy.deepcopy(online.model)
    old.online_fit = ONLINE_FIT_VERSION - 1
    save_cost_model(old, path)
    with pytest.warns(UserWarning, match="earlier version of the online fit"):
        got = load_cost_model("test", path)
    assert (
        got.adapted_frames == 0 and got.coefficients["raycast"] == calibrated.coefficients["raycast"]
    )  # the calibration serves again


def test_exploring_is_charged_what_the_frame_cost_beyond_its_chosen_passes():
    """An explored frame is charged its measured ms beyond the chosen strategy's pass measured in it, the explored
    tiles' predicted ms in that strategy and the gap one-strategy frames leave around their pass, however far the
    model's prediction of the frame as chosen is off."""
    rng = np.random.default_rng(16)
    online = OnlineModel(scaled(TRUE, "raster", 1.5))  # predicts raster frames 1.5x too costly
    cols = columns(rng, 10)
    chosen = np.array(["raster"] * 10, dtype=object)
    for _ in range(4):  # one-strategy frames measured at 1.1x their pass
        passes = true_passes(cols, chosen, rng, noise=0.0)
        online.observe(cols, chosen.tolist(), passes, 1.1 * passes["raster"], None, 1.5 * passes["raster"])
    gap = 0.1 * passes["raster"]
    chosen[:2] = "raycast"
    passes = true_passes(cols, chosen, rng, noise=0.0)
    online.observe(cols, chosen.tolist(), passes, sum(passes.values()))  # raycast's first pass: one-off costs
    online.credit = 10.0
    rest = 0.8 * passes["raster"]  # the chosen pass, on the tiles not explored
    passes = {"raster": rest, "raycast": 3.0}  # the explored pass: 2 ms beyond the tiles' 1 ms as raster
    frame = rest + 3.0 + gap + 6.0  # and 6 ms more around the passes (split timing, a depth copy)
    online.observe(cols, chosen.tolist(), passes, frame, Exploration("raycast", np.arange(2), 1.0, True))
    assert online.stats.explore_ms == pytest.approx(8.0)  # 2 ms in the pass and 6 around it
    assert online.credit == pytest.approx(10.0 + 0.05 * frame - 8.0)


def test_a_candidate_the_budget_cannot_pay_for_does_not_hold_back_one_it_can():
    """The candidate known least goes first only among those the budget covers: a costly unknown one waits while a
    cheap one with a row already is explored."""
    rng = np.random.default_rng(4)
    online = OnlineModel(TRUE, AdaptOptions(explore_share=0.05))
    cols = columns(rng, 20)
    names = TRUE.candidates
    table = TRUE.predict_table(cols)
    g, c = names.index("raster_gs"), names.index("raycast")
    table[g] += 50.0  # exploring raster_gs would cost far more than the credit
    picks = np.full(20, names.index("raster"))
    online.rows["raycast"].add(np.ones(1 + len(TERMS["raycast"])), 5.0)  # raycast known a little, raster_gs not
    online.credit = TRUE.overhead["raycast"] + TRUE.mix_overhead + 2 * float(table[c].max()) + 1.0
    found = [online.explore(table, picks.copy(), names) for _ in range(10)]
    assert all(e is not None and e.strategy == "raycast" for e in found)
    table[c] += 50.0  # now neither is affordable
    assert online.explore(table, picks.copy(), names) is None


def test_a_strategy_the_others_rows_price_up_is_explored_at_its_starting_level():
    """Ray casting drawn at 5x its model sets the machine's scale; raster, never drawn and right in the model, is
    still offered its two tiles at the starting level, where the scaled price would be beyond the credit."""
    rng = np.random.default_rng(21)
    online = OnlineModel(scaled(TRUE, "raycast", 0.2))
    cols = columns(rng, 12)
    chosen = np.array(["raycast"] * 12, dtype=object)
    for _ in range(4):
        online.observe(cols, chosen.tolist(), true_passes(cols, chosen, rng, noise=0.0), 30.0)
    assert online.machine_scale() > 3.0
    names = online.model.candidates
    table = online.model.predict_table(cols)
    picks = np.full(12, names.index("raycast"))
    r = names.index("raster")
    start = online.start.predict_table(cols)[r]
    online.credit = online.start.overhead["raster"] + float(np.sort(start)[:4].sum()) + online.model.mix_overhead
    scaled_price = online.model.overhead["raster"] + float(np.sort(table[r])[:2].sum())
    assert scaled_price > online.credit  # what the machine's scale asks for two tiles
    found = [online.explore(table, picks.copy(), names) for _ in range(10)]
    assert any(e is not None and e.strategy == "raster" for e in found)


def _observed(seed: int, most: str, first_two: str, frames: int):
    """(online model, rng, columns) after ``frames`` observed frames of 12 tiles: the first two drawn by
    ``first_two``, the rest by ``most``."""
    rng = np.random.default_rng(seed)
    online = OnlineModel(TRUE)
    cols = columns(rng, 12)
    chosen = np.array([most] * 12, dtype=object)
    chosen[:2] = first_two
    for _ in range(frames):
        online.observe(cols, chosen.tolist(), true_passes(cols, chosen, rng), 30.0)
    return online, rng, cols


def test_a_strategy_seen_on_a_few_tiles_is_given_a_whole_frame_until_it_drew_some():
    """After its first pass (a few tiles, compiles), a strategy that might beat the frame is given every tile of
    a frame the budget covers, until it drew ``level_rows`` such passes; then a few tiles again."""
    online, rng, cols = _observed(22, "raycast", "raster", 1)  # raster's first pass
    names = TRUE.candidates
    table = TRUE.predict_table(cols)
    r, c = names.index("raster"), names.index("raycast")
    table[r] = 0.5 * table[c]  # raster would beat the frame
    table[names.index("raster_gs")] = np.inf  # cannot draw these tiles: not a candidate here
    picks = np.full(12, c)
    online.credit = 50.0
    for _ in range(AdaptOptions().level_rows):
        e = online.explore(table, picks.copy(), names)
        assert e is not None and e.strategy == "raster" and len(e.tiles) == 12
        whole = np.array(["raster"] * 12, dtype=object)
        online.observe(cols, whole.tolist(), true_passes(cols, whole, rng), 20.0, e)
        online.credit = 50.0
    e = online.explore(table, picks.copy(), names)
    assert e is None or len(e.tiles) <= AdaptOptions().explore_tiles


def test_a_strategy_never_drawn_is_explored_before_another_is_given_a_whole_frame():
    """Of the candidates the budget covers, the one known least goes first: a strategy with no pass yet gets its
    few tiles before one already seen is given a whole frame, and its price leaves out the machine's scale."""
    online, _, cols = _observed(23, "raster", "raster_gs", 2)  # raster_gs's first pass (uncharged), then a row each
    names = TRUE.candidates
    table = TRUE.predict_table(cols)
    r, g = names.index("raster"), names.index("raster_gs")
    table[g] = 0.5 * table[r]  # raster_gs might beat the frame: a whole frame would be offered it alone
    online.credit = 50.0
    e = online.explore(table, np.full(12, r), names)
    assert e is not None and e.strategy == "raycast" and len(e.tiles) <= AdaptOptions().explore_tiles


def test_a_strategy_never_drawn_is_priced_at_the_starting_level_on_a_slower_machine():
    """On a machine 8x slower than the starting model, a strategy never drawn carries that scale in the model's
    overhead, but exploration prices it at the starting model's level, so the budget can still reach it."""
    rng = np.random.default_rng(24)
    online = OnlineModel(TRUE)
    cols = columns(rng, 12)
    chosen = ["raster"] * 12
    for _ in range(2 + AdaptOptions().level_rows):
        passes = {k: 8.0 * v for k, v in true_passes(cols, np.array(chosen, dtype=object), rng).items()}
        online.observe(cols, chosen, passes, 8.0 * sum(passes.values()))
    assert online.machine_scale() > 6.0
    scaled_overhead = online.model.overhead["raycast"]
    assert scaled_overhead > 6.0 * TRUE.overhead["raycast"]
    online.credit = 2.0 * TRUE.overhead["raycast"]  # covers the starting level, far from the scaled one
    assert online.credit < scaled_overhead and online.may_explore({"raster"})
