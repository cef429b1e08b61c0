"""The cost model: the fit recovers known coefficients; the choice follows the predicted costs; files round-trip."""

import json

import numpy as np
import pytest
from cost_helpers import true_model

from hybrid.camera.view import View
from hybrid.cost.features import TileFeatures, _hull_area_clipped, footprint_pixels
from hybrid.cost.fit import FrameSample, TileSample, estimate_overhead, fit_frames, frame_design
from hybrid.cost.model import TERMS, CostModel, load_cost_model, save_cost_model, term_values
from hybrid.cost.planner import choose
from hybrid.errors import TerrabenchError
from hybrid.residency import ResidencyCache

TRUE = true_model()


def synthetic_tiles(n=300, seed=0):
    rng = np.random.default_rng(seed)
    return [
        TileFeatures(
            float(rng.uniform(10, 50000)),
            float(rng.uniform(0, 130000)),
            float(rng.uniform(0, 300)),
            int(rng.integers(0, 3)),
            float(rng.uniform(1e3, 1e5)),
            float(rng.uniform(0.05, 1.0)),
            float(rng.uniform(0, 40000)),
        )
        for _ in range(n)
    ]


OVERHEAD = {"raster": 2.0, "raster_gs": 3.0, "raycast": 1.5}
MIX = 1.2
NAMES = ("raster", "raster_gs", "raycast")


def synthetic_frames(n=240, seed=0, noise=0.005, names=NAMES, mix=MIX):
    """Frames of 4-30 synthetic tiles, pure and assigned at random, timed by TRUE plus OVERHEAD per strategy used
    and ``mix`` where more than one is used."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        count = int(rng.integers(4, 31))
        feats = synthetic_tiles(count, seed=seed * 1000 + k)
        a = np.array([names[k % len(names)]] * count) if k % 4 == 0 else rng.choice(names, size=count)
        terms = {s: np.array([term_values(f, s) for f in feats]) for s in names}
        ms = sum(
            OVERHEAD[s] + sum(TRUE.predict(f)[s] for f, c in zip(feats, a) if c == s) for s in names if (a == s).any()
        )
        ms += mix * (len(set(a.tolist())) > 1)
        out.append(
            FrameSample(
                {s: bool((a == s).any()) for s in names},
                {s: terms[s][a == s].sum(axis=0) for s in names},
                float(ms * rng.normal(1, noise)),
            )
        )
    return out


def test_frame_fit_recovers_known_coefficients_and_overheads():
    frames = synthetic_frames()
    m = fit_frames(frames, "test", holdout=0.3)
    assert m.candidates == NAMES and m.frames == 240
    total = np.mean([f.ms for f in frames])
    for s in NAMES:
        for i, (t, v) in enumerate(TRUE.coefficients[s].items()):
            share = v * np.mean([f.sums[s][i] for f in frames]) / total  # of the frames' time
            # a term under a tenth of the time is weakly seen at this noise (0.5 %): within 60 %, else 25 %
            assert np.isclose(m.coefficients[s][t], v, rtol=0.25 if share >= 0.1 else 0.6), (
                s,
                t,
                m.coefficients[s][t],
                v,
            )
        assert np.isclose(m.overhead[s], OVERHEAD[s], rtol=0.25), (s, m.overhead[s])
        assert m.fit_error[s] < 0.01  # held-out frames: about the noise
    assert np.isclose(m.mix_overhead, MIX, rtol=0.25), m.mix_overhead
    assert 0 < m.mix_error < 0.01 and "of mixed frames" in m.explain()  # the frames given tiles at random
    assert "a frame mixing strategies adds 1." in m.explain()
    # frames whose mixing costs nothing more get no mixed-frame overhead; one that costs more, ignored, is
    # predicted worse than the noise: the column is what takes it up
    assert fit_frames(synthetic_frames(mix=0.0), "test", holdout=0.3).mix_overhead < 0.1
    X = frame_design(synthetic_frames(), NAMES)
    assert X.shape[1] == 18 and set(X[:, -1]) == {0.0, 1.0}
    costly = fit_frames(synthetic_frames(mix=4.0), "test", holdout=0.3)
    assert np.isclose(costly.mix_overhead, 4.0, rtol=0.1) and costly.mix_error < 0.01
    mixed = {"raster", "raycast"}
    assert costly.frame_ms([1.0, 2.0], mixed) == pytest.approx(
        3.0 + costly.overhead["raster"] + costly.overhead["raycast"] + costly.mix_overhead
    )
    assert costly.frame_ms([1.0, 2.0], {"raster"}) == pytest.approx(3.0 + costly.overhead["raster"])
    assert "of 240 frames' times" in m.explain() and "raster_gs ms = " in m.explain()
    two = fit_frames(synthetic_frames(names=("raster", "raycast")), "test", names=("raster", "raycast"))
    assert two.candidates == ("raster", "raycast") and "raster_gs not calibrated: never chosen" in two.explain()


CALL = {"raster": 0.8, "raster_gs": 0.6, "raycast": 0.9}


def synthetic_single_calls(n=150, seed=1, noise=0.005):
    """Tiles drawn one call each: TRUE's per-tile cost plus CALL, every candidate way."""
    rng = np.random.default_rng(seed)
    return [
        TileSample(s, term_values(f, s), float((TRUE.predict(f)[s] + CALL[s]) * rng.normal(1, noise)))
        for f in synthetic_tiles(n, seed)
        for s in NAMES
    ]


def test_joint_fit_recovers_the_per_call_overhead_and_holds_tiles_out():
    """Frames and tiles timed one call each share the coefficients; each strategy's per-call overhead is fitted
    with them, and the held-out tiles are predicted within the noise, as the held-out frames."""
    tiles = synthetic_single_calls()
    m = fit_frames(synthetic_frames(), "test", holdout=0.3, tiles=tiles)
    assert m.tiles == len(tiles) and set(m.call_overhead) == set(NAMES)
    for s in NAMES:
        assert np.isclose(m.call_overhead[s], CALL[s], rtol=0.1), (s, m.call_overhead[s])
        assert np.isclose(m.overhead[s], OVERHEAD[s], rtol=0.25), (s, m.overhead[s])
        assert m.tile_error[s] < 0.01 and m.fit_error[s] < 0.01
    assert "per-call overhead of a tile drawn as its own call" in m.explain()
    # without the tiles there is no per-call overhead nor tile error; a bad tile time is refused
    plain = fit_frames(synthetic_frames(), "test", holdout=0.3)
    assert plain.call_overhead == {} and plain.tile_error == {}
    with pytest.raises(TerrabenchError, match="one call each need finite times"):
        fit_frames(synthetic_frames(), "test", tiles=tiles[:-1] + [TileSample("raster", tiles[0].terms, float("nan"))])


def test_frame_fit_rejects_bad_timings():
    frames = synthetic_frames(40)
    with pytest.raises(TerrabenchError, match="finite times > 0"):
        fit_frames(frames[:-1] + [FrameSample(frames[0].used, frames[0].sums, 0.0)], "t")
    with pytest.raises(TerrabenchError, match="at least 18 frames"):
        fit_frames(frames[:10], "t")
    with pytest.raises(TerrabenchError, match="holdout"):
        fit_frames(frames, "t", holdout=1.0)
    with pytest.raises(KeyError):
        fit_frames(frames, "t", names=("raster", "raycast", "tin"))
    assert [len(TERMS[s]) for s in NAMES] == [5, 5, 4]


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
    costly_rays = CostModel(
        "x",
        {
            "raster": TRUE.coefficients["raster"],
            "raycast": {"const": 5.0, "pixels": 1e-3, "surface_pixels": 0.0, "pixel_steps": 1e-3},
        },
    )
    assert choose("hybrid", rough_big, costly_rays.predict(rough_big)) == "raster"
    assert choose("heuristic", rough_big, b) == "raycast" and choose("heuristic", flat_small, a) == "raster"
    with pytest.raises(TerrabenchError, match="unknown policy"):
        choose("fastest", flat_small, a)


def test_save_load_by_renderer(tmp_path):
    p = tmp_path / "costs.json"
    save_cost_model(TRUE, p)
    got = load_cost_model("test", p)
    assert got.coefficients == TRUE.coefficients
    fitted = CostModel(
        "fitted",
        dict(TRUE.coefficients),
        call_overhead=dict(CALL),
        tile_error={"raster": 0.1},
        mix_overhead=1.25,
        full_res="lean",
    )
    save_cost_model(fitted, p)
    again = load_cost_model("fitted", p)
    assert again.call_overhead == CALL and again.tile_error == {"raster": 0.1} and again.mix_overhead == 1.25
    assert again.full_res == "lean" and "full_res 'lean'" in again.explain()
    data = json.loads(p.read_text())
    del data["fitted"]["full_res"]  # saved before models named their rule
    p.write_text(json.dumps(data))
    assert load_cost_model("fitted", p).full_res == "exact"
    data["fitted"]["full_res"] = "half"
    p.write_text(json.dumps(data))
    with pytest.raises(TerrabenchError, match=r"malformed cost model .full_res must be one of exact, lean, got 'half'"):
        load_cost_model("fitted", p)
    shipped = load_cost_model("llvmpipe (LLVM 15.0.6, 256 bits)", p)
    assert "llvmpipe" in shipped.source
    other = load_cost_model("Some Unknown GPU", p)
    assert "fallback" in other.source
    # saved under a part of the renderer string (calibrate --key), as the shipped file keys its models: found
    # for the full string whatever its case, the longest such key first, in the user's file before the shipped
    save_cost_model(CostModel("NVIDIA H200", dict(TRUE.coefficients), mix_overhead=0.5), p)
    save_cost_model(CostModel("NVIDIA", dict(TRUE.coefficients), mix_overhead=0.25), p)
    gpu = load_cost_model("NVIDIA H200/PCIe/SSE2", p)
    assert gpu.mix_overhead == 0.5 and "'NVIDIA H200'" in gpu.source
    assert load_cost_model("nvidia h200/pcie/sse2", p).mix_overhead == 0.5
    assert load_cost_model("NVIDIA H100/PCIe/SSE2", p).mix_overhead == 0.25
    assert "llvmpipe" in load_cost_model("llvmpipe (LLVM 15.0.6, 256 bits)", p).source
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
    assert footprint_pixels(v, np.array([-1, -200, -1.0]), np.array([1, -150, 1.0])) == 0.0  # wholly behind
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
    assert c.get("raster", s, "a", lambda: 100) is a and c.stats.hits == 1  # resident: not uploaded again
    c.get("raycast", s, "c", lambda: 100)  # evicts b (least recent)
    assert c.bytes == 200 and c.stats.evictions == 1 and ("raster", "b") not in c.entries
    assert c.bytes_by_strategy() == {"raster": 100, "raycast": 100}
    with pytest.raises(TerrabenchError, match="too small"):
        c.get("raster", s, "d", lambda: 300)
    with pytest.raises(TerrabenchError, match="budget"):
        ResidencyCache(-1)


def test_a_model_saved_with_per_strategy_keys_still_loads(tmp_path):
    legacy = {"renderer": "old", **{s: dict(c) for s, c in TRUE.coefficients.items()}, "mix_overhead": 0.5}
    p = tmp_path / "costs.json"
    p.write_text(json.dumps({"old": legacy}))
    got = load_cost_model("old", p)
    assert got.coefficients == TRUE.coefficients and got.mix_overhead == 0.5
    del legacy["raycast"]
    p.write_text(json.dumps({"old": legacy}))
    with pytest.raises(TerrabenchError, match=r"malformed cost model.*raycast"):
        load_cost_model("old", p)
