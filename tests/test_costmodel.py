"""The cost model: the fit recovers known coefficients; the choice follows the predicted costs; files round-trip."""

import numpy as np
import pytest

from hybrid.camera.view import View
from hybrid.cost.features import TileFeatures, _hull_area_clipped, footprint_pixels
from hybrid.cost.fit import estimate_overhead, fit_cost_model, fit_strategy, median_rel_error
from hybrid.cost.model import CostModel, load_cost_model, save_cost_model
from hybrid.cost.planner import choose
from hybrid.errors import TerrabenchError
from hybrid.residency import ResidencyCache

TRUE = CostModel("test", {"const": 0.3, "triangles": 5e-5, "visible_triangles": 1.5e-4, "pixels": 1e-5},
                 {"const": 0.5, "pixels": 2e-5, "surface_pixels": 1e-5, "pixel_steps": 1e-5},
                 raster_gs={"const": 0.2, "triangles": 2e-4, "visible_triangles": 3e-4, "pixels": 1e-5})


def synthetic_tiles(n=300, seed=0):
    rng = np.random.default_rng(seed)
    return [TileFeatures(float(rng.uniform(10, 50000)), float(rng.uniform(0, 130000)), float(rng.uniform(0, 300)),
                         int(rng.integers(0, 3)), float(rng.uniform(1e3, 1e5)), float(rng.uniform(0.05, 1.0)),
                         float(rng.uniform(0, 40000)))
            for _ in range(n)]


def test_fit_recovers_known_coefficients():
    feats = synthetic_tiles()
    rng = np.random.default_rng(1)
    times = {s: np.array([TRUE.predict(f)[s] for f in feats]) * rng.normal(1, 0.02, len(feats))
             for s in ("raster", "raster_gs", "raycast")}
    m = fit_cost_model(feats, times, "test")
    assert m.candidates == ("raster", "raster_gs", "raycast")
    for s in ("raster", "raster_gs", "raycast"):
        for t, v in getattr(TRUE, s).items():
            assert np.isclose(getattr(m, s)[t], v, rtol=0.1), (s, t)
        assert m.fit_error[s] < 0.03                          # held-out median relative error ~ the noise
    assert "raster_gs ms = " in m.explain() and "never chosen" not in m.explain()
    two = fit_cost_model(feats, {s: times[s] for s in ("raster", "raycast")}, "test")
    assert two.candidates == ("raster", "raycast") and "raster_gs not calibrated: never chosen" in two.explain()


@pytest.mark.parametrize("strategy", ["raster", "raycast"])
def test_fit_strategy_takes_the_overhead_off(strategy):
    # single-tile times include the per-frame overhead once; the fit must return the per-tile coefficients
    feats = synthetic_tiles(200, seed=2)
    overhead = 1.7
    noise = np.random.default_rng(3).normal(1, 0.01, len(feats))
    ms = np.array([TRUE.predict(f)[strategy] for f in feats]) * noise + overhead
    coef = fit_strategy(feats, ms, strategy, overhead)
    want = getattr(TRUE, strategy)
    assert coef.keys() == want.keys()
    for t, v in want.items():
        assert np.isclose(coef[t], v, rtol=0.1), (t, coef[t], v)
    m = CostModel("t", TRUE.raster, TRUE.raycast, overhead={"raster": 0.0, "raycast": 0.0, strategy: overhead})
    setattr(m, strategy, coef)
    assert median_rel_error(m, feats, ms, strategy) < 0.01
    # a model that forgets the overhead is off by it on every tile
    m.overhead[strategy] = 0.0
    assert median_rel_error(m, feats, ms, strategy) > 0.05


def test_estimate_overhead_recovers_a_known_overhead():
    # a frame of k tiles: each drawn alone costs c_i + O, all together sum(c_i) + O
    rng = np.random.default_rng(4)
    O = 2.5
    singles, together = [], []
    for k in (2, 3, 5, 8):
        c = rng.uniform(0.1, 6.0, k)
        singles.append(c + O)
        together.append(float(c.sum()) + O)
    assert np.isclose(estimate_overhead(singles, together), O)
    # frames of one tile say nothing about the overhead; none at all gives 0
    assert np.isclose(estimate_overhead(singles + [np.array([9.0])], together + [1.0]), O)
    assert estimate_overhead([np.array([3.0])], [3.0]) == 0.0 and estimate_overhead([], []) == 0.0
    # together slower than the singles' sum (no shared overhead): clamped at 0, never negative
    assert estimate_overhead([np.array([1.0, 1.0])], [2.5]) == 0.0


def test_choice_follows_predicted_costs():
    flat_small = TileFeatures(pixels=20000, triangles=512, slab_cells=0.5, level=0, distance=5e3, surface_pixels=15000)
    rough_big = TileFeatures(pixels=60000, triangles=131072, slab_cells=40, level=0, distance=5e3, surface_pixels=40000)
    a, b = TRUE.predict(flat_small), TRUE.predict(rough_big)
    assert a["raster"] < a["raycast"] and b["raycast"] < b["raster"]
    assert choose("hybrid", flat_small, a) == "raster"
    assert choose("hybrid", rough_big, b) == "raycast"
    # the same tiles under a device where rays are very expensive go to raster both
    costly_rays = CostModel("x", TRUE.raster, {"const": 5.0, "pixels": 1e-3, "surface_pixels": 0.0, "pixel_steps": 1e-3})
    assert choose("hybrid", rough_big, costly_rays.predict(rough_big)) == "raster"
    assert choose("heuristic", rough_big, b) == "raycast" and choose("heuristic", flat_small, a) == "raster"
    with pytest.raises(TerrabenchError, match="unknown policy"):
        choose("fastest", flat_small, a)


def test_fit_rejects_bad_timings():
    feats = synthetic_tiles(10)
    with pytest.raises(TerrabenchError, match="finite and > 0"):
        fit_cost_model(feats, {"raster": np.zeros(10), "raycast": np.ones(10)}, "t")
    with pytest.raises(TerrabenchError, match="at least 4"):
        fit_cost_model(feats[:2], {"raster": np.ones(2), "raycast": np.ones(2)}, "t", holdout=0.0)
    with pytest.raises(TerrabenchError, match="without raycast times"):
        fit_cost_model(feats, {"raster": np.ones(10)}, "t")
    with pytest.raises(TerrabenchError, match="no cost terms for tin"):
        fit_cost_model(feats, {"raster": np.ones(10), "raycast": np.ones(10), "tin": np.ones(10)}, "t")


def test_save_load_by_renderer(tmp_path):
    p = tmp_path / "costs.json"
    save_cost_model(TRUE, p)
    got = load_cost_model("test", p)
    assert got.raster == TRUE.raster and got.raycast == TRUE.raycast and got.raster_gs == TRUE.raster_gs
    shipped = load_cost_model("llvmpipe (LLVM 15.0.6, 256 bits)", p)
    assert "llvmpipe" in shipped.source
    other = load_cost_model("Some Unknown GPU", p)
    assert "fallback" in other.source
    p.write_text("{broken")
    with pytest.raises(TerrabenchError, match="not valid JSON"):
        load_cost_model("test", p)


def test_footprint_of_box():
    assert np.isclose(_hull_area_clipped(np.array([[-10, -10], [20, -10], [20, 20], [-10, 20.0]]), 10, 10), 100)
    assert np.isclose(_hull_area_clipped(np.array([[0, 0], [4, 0], [0, 4.0]]), 10, 10), 8)
    v = View([0, -100, 0], [0, 0, 0], 90, 100, 100, 1, 1e4)
    # a 2 x 2 m square facing the camera 100 m away at fov 90: 1 m = 0.5 px -> 1 px²
    a = footprint_pixels(v, np.array([-1, 0, -1.0]), np.array([1, 0, 1.0]))
    assert np.isclose(a, 1.0, rtol=1e-6)
    # a box reaching behind the eye is cut at the near plane: the 2 x 2 m section 1 m ahead fills the view
    assert np.isclose(footprint_pixels(v, np.array([-1, -200, -1.0]), np.array([1, 0, 1.0])), 100 * 100)
    assert footprint_pixels(v, np.array([-1, -200, -1.0]), np.array([1, -150, 1.0])) == 0.0     # wholly behind
    # eye inside a long box: the near-plane section (2 x 2 m at 1 m) covers the whole 90-degree view
    assert np.isclose(footprint_pixels(v, np.array([-1, -101, -1.0]), np.array([1, 0, 1.0])), 100 * 100)


class _Fake:
    def __init__(self, n):
        self.nbytes, self.released = n, False

    def release(self):
        self.released = True


class _Strategy:
    def upload(self, tile):
        return _Fake(tile)


def test_residency_budget_and_lru():
    c = ResidencyCache(250)
    s = _Strategy()
    a = c.get("raster", s, "a", lambda: 100)
    c.get("raster", s, "b", lambda: 100)
    assert c.get("raster", s, "a", lambda: 100) is a and c.stats.hits == 1     # resident: not uploaded again
    c.get("raycast", s, "c", lambda: 100)                                       # evicts b (least recent)
    assert c.bytes == 200 and c.stats.evictions == 1 and ("raster", "b") not in c.entries
    assert c.bytes_by_strategy() == {"raster": 100, "raycast": 100}
    with pytest.raises(TerrabenchError, match="too small"):
        c.get("raster", s, "d", lambda: 300)
    with pytest.raises(TerrabenchError, match="budget"):
        ResidencyCache(-1)
