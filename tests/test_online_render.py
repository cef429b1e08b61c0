"""The adapting hybrid on real frames: predictions move toward the measured drawing, exploration keeps to its
budget, mixed frames time each strategy's pass, and a frozen hybrid chooses the same on every run."""

import copy

import numpy as np
import pytest

from hybrid.camera.flight import preset
from hybrid.cost.model import load_cost_model
from hybrid.cost.online import AdaptOptions
from hybrid.gl.context import gl_info
from hybrid.renderer import Renderer


@pytest.fixture(scope="module")
def flight(puget257):
    return preset("flyover", puget257, 24, 320, 180).views()


def skewed(ctx, factor=0.2):
    """This device's model with every ray-casting coefficient and its overhead multiplied by factor."""
    m = copy.deepcopy(load_cost_model(gl_info(ctx).renderer))
    m.coefficients = {**m.coefficients, "raycast": {k: v * factor for k, v in m.coefficients["raycast"].items()}}
    m.overhead = {**m.overhead, "raycast": m.overhead["raycast"] * factor}
    return m


def prediction_errors(r, views, tau=2 / 3):
    """Per frame |predicted - measured| / measured of the drawing, as the hybrid drew it."""
    out = []
    for v in views:
        st = r.render(v, tau, read=False).stats
        out.append(abs(st.pred_ms - st.draw_ms) / st.draw_ms)
    return np.array(out)


def test_adaptation_from_a_wrong_model_moves_predictions_toward_measured(ctx, puget257, flight):
    with Renderer(ctx, puget257, "hybrid", 64, cost_model=skewed(ctx), reuse_choice=1) as r:
        errors = prediction_errors(r, flight)  # every frame planned, so every frame predicted
        assert r.online.stats.refits > 0
        assert r.model.adapted_frames > 0 and "adapted online" in r.model.source
    with Renderer(ctx, puget257, "hybrid", 64, cost_model=skewed(ctx), adapt=False) as frozen:
        frozen_errors = prediction_errors(frozen, flight)
    assert np.median(frozen_errors[8:]) > 0.4  # the wrong model stays wrong when frozen
    assert np.median(errors[8:]) < 0.5 * np.median(frozen_errors[8:])


def test_exploration_keeps_to_its_budget(ctx, puget257, flight):
    opts = AdaptOptions(explore_share=0.05)
    with Renderer(ctx, puget257, "hybrid", 64, cost_model=skewed(ctx, 5.0), adapt=opts, reuse_choice=1) as r:
        explored = sum(r.render(v, 2 / 3, read=False).stats.explored_tiles for v in flight * 3)
        st = r.online.stats
    assert st.frames >= 60
    assert explored == st.explored_tiles
    # the budget is charged what each exploration measured; one exploration may overdraw it by its own cost
    assert st.explore_ms <= 0.05 * st.frame_ms + max(r.online._spent.values(), default=0.0)


def test_mixed_frames_time_each_pass(ctx, puget257, flight):
    from hybrid import adaptive

    seen = []
    explore = AdaptOptions(explore_share=0.3)  # a budget that mixes frames early, whatever this device's model
    with Renderer(ctx, puget257, "hybrid", 64, cost_model=skewed(ctx), adapt=explore, reuse_choice=1) as r:
        real = adaptive.observe

        def spy(online, plans, passes, draw_ms, explored, predicted):
            seen.append((sorted({p.choice for p in plans}), passes, draw_ms))
            real(online, plans, passes, draw_ms, explored, predicted)

        adaptive.observe = spy
        try:
            for v in flight:
                r.render(v, 2 / 3, read=False)
        finally:
            adaptive.observe = real
    assert any(len(used) > 1 for used, _, _ in seen)  # exploration mixes frames, if nothing else
    for used, passes, draw in seen:
        assert sorted(passes) == used  # one timed pass per strategy drawn
        assert all(ms > 0 for ms in passes.values())
        assert sum(passes.values()) <= draw * 1.05 + 0.5  # the passes lie inside the drawing


def test_frozen_hybrid_chooses_the_same_every_run(ctx, puget257, flight):
    runs = []
    for _ in range(2):
        with Renderer(ctx, puget257, "hybrid", 64, cost_model=skewed(ctx), adapt=False) as r:
            runs.append([[p.choice for p in r.render(v, 2 / 3, read=False).plans] for v in flight[:8]])
            assert r.online is None
    assert runs[0] == runs[1]


def test_a_frames_prediction_is_made_before_the_model_learns_from_it(ctx, puget257, flight):
    """pred_ms is the model's prediction of the frame as it was before the frame: on a frame that refits the
    model, the refitted model would predict it otherwise."""
    import copy

    from hybrid.cost.planner import predicted_frame_ms

    differed = 0
    with Renderer(ctx, puget257, "hybrid", 64, cost_model=skewed(ctx), reuse_choice=1) as r:
        for v in flight:
            before, refits = copy.deepcopy(r.model), r.online.stats.refits
            st = r.render(v, 2 / 3, read=False).stats
            assert st.pred_ms == predicted_frame_ms(before, st.plans)
            if r.online.stats.refits > refits:
                differed += predicted_frame_ms(r.model, st.plans) != st.pred_ms
    assert differed > 0
