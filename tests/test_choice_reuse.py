"""A clear pure choice reused between full plans (hybrid.cost.reuse): when, and that its frames draw the same."""

import copy

import numpy as np
import pytest

from hybrid.camera.flight import preset
from hybrid.cost.model import load_cost_model
from hybrid.cost.planner import plan_frame, pure_slack
from hybrid.cost.reuse import ChoiceReuse
from hybrid.errors import TerrabenchError
from hybrid.gl.context import gl_info
from hybrid.renderer import Renderer
from hybrid.tiles.pyramid import TilePyramid


def only(ctx, keep: str, others: float = 1e6):
    """This device's model with every other candidate's per-frame overhead set to ``others`` ms."""
    m = copy.deepcopy(load_cost_model(gl_info(ctx).renderer))
    m.overhead = {s: (v if s == keep else others) for s, v in m.overhead.items()}
    return m


def test_reuse_follows_the_last_full_plan():
    r = ChoiceReuse(frames=3, slack=0.1)
    assert r.take() is None and not r.reused
    r.planned(("raster", 0.5), allowed=True)
    assert [r.take() for _ in range(3)] == ["raster", "raster", None]  # then plan in full again
    r.planned(("raster", 0.05), allowed=True)  # another strategy within the slack: no reuse
    assert r.take() is None
    r.planned(("raycast", 0.5), allowed=False)
    assert r.take() is None
    r.planned(None, allowed=True)  # a mixed frame
    assert r.take() is None
    with pytest.raises(TerrabenchError, match="frames >= 1"):
        ChoiceReuse(frames=0)


def test_pure_slack_reads_what_the_other_strategies_fall_short_by(ctx, puget257):
    """Forced to raster by the others' overheads, the slack is about those overheads over the frame; where they cost
    nothing the others are taken, and a frame that mixes has none."""
    pyramid = TilePyramid(puget257, 64)
    view = preset("flyover", puget257, 4, 320, 180).view(1)
    model = only(ctx, "raster", 1e3)
    plans = plan_frame(pyramid, view, model)
    assert {p.choice for p in plans} == {"raster"}
    choice, slack = pure_slack(plans, model)
    frame = sum(p.cost("raster") for p in plans) + model.overhead["raster"]
    assert choice == "raster" and 1e3 / frame * 0.9 < slack < 1e3 / frame
    for p in plans[:2]:
        p.choice = "raycast"
    assert pure_slack(plans, model) is None


def test_reused_frames_draw_what_full_plans_draw(ctx, puget257):
    """A frozen hybrid forced to one strategy plans in full every fourth frame and reuses the choice between; its
    reused frames draw the same image as a hybrid planning every frame, and a hybrid whose choice mixes never
    reuses."""
    views = preset("flyover", puget257, 8, 320, 180).views()
    model = only(ctx, "raster")
    kw = {"cost_model": model, "adapt": False}
    with (
        Renderer(ctx, puget257, "hybrid", 64, **kw) as a,
        Renderer(ctx, puget257, "hybrid", 64, reuse_choice=1, **kw) as b,
    ):
        got = [a.render(v, 2 / 3) for v in views]
        want = [b.render(v, 2 / 3) for v in views]
    assert [g.stats.choice_reused for g in got] == [False, True, True, True] * 2
    assert not any(w.stats.choice_reused for w in want)
    for g, w in zip(got, want):
        assert [p.choice for p in g.plans] == [p.choice for p in w.plans]
        assert np.array_equal(g.colour, w.colour) and np.array_equal(g.distance, w.distance, equal_nan=True)
    assert got[1].stats.pred_ms is None and got[4].stats.pred_ms is not None  # reused frames are not priced
    mixing = copy.deepcopy(model)
    mixing.overhead = dict.fromkeys(mixing.overhead, 0.0)
    mixing.coefficients = {**mixing.coefficients, "raycast": dict.fromkeys(mixing.coefficients["raycast"], 0.0)}
    with Renderer(ctx, puget257, "hybrid", 64, cost_model=mixing, adapt=False) as r:
        stats = [r.render(v, 2 / 3, read=False).stats for v in views[:4]]
    assert not any(s.choice_reused for s in stats) and all(s.tiles_raycast > 0 for s in stats)


@pytest.mark.parametrize("hold_error", [0.0, 100.0])
def test_an_adapting_hybrid_reuses_once_its_choice_holds(ctx, puget257, hold_error):
    """Adapting, the hybrid reuses its clear choice only after that strategy's predictions hold: never where no
    error is small enough, and soon after ``hold_rows`` passes where any error is."""
    from hybrid.cost.online import AdaptOptions

    views = preset("flyover", puget257, 12, 320, 180).views()
    opts = AdaptOptions(hold_error=hold_error)
    with Renderer(ctx, puget257, "hybrid", 64, cost_model=only(ctx, "raster"), adapt=opts) as r:
        reused, holds = [], []
        for v in views:
            reused.append(r.render(v, 2 / 3, read=False).stats.choice_reused)
            holds.append(r.online.holds("raster"))
    if hold_error == 0.0:
        assert not any(reused) and not any(holds)
    else:
        first = holds.index(True)
        assert opts.hold_rows - 1 <= first <= opts.hold_rows  # a strategy's first pass is no row
        assert not any(reused[: first + 1])
        assert reused[first + 2 : first + 5] == [True, True, True]
