"""The bench's reading of the cost model's per-tile error: raw, and with the run's one scale factor."""

import numpy as np
import pandas as pd
import pytest

from experiments.bench_hybrid import SCALED, tile_errors
from hybrid.cost.model import CostModel

STRATEGIES = ("raster", "raster_gs", "raycast")


def _model() -> CostModel:
    coef = {"const": 0.1}
    return CostModel(
        "test",
        {"raster": dict(coef), "raycast": dict(coef), "raster_gs": dict(coef)},
        call_overhead=dict.fromkeys(STRATEGIES, 0.0),
    )


def _tiles(factor: dict, noise: float = 0.0, n: int = 400, seed: int = 3) -> pd.DataFrame:
    """Tiles whose predicted ms are measured x factor[strategy] x (1 + uniform noise)."""
    rng = np.random.default_rng(seed)
    cols = {"flight": ["orbit"] * n, "frame": np.arange(n) // 20}
    for s in STRATEGIES:
        meas = rng.uniform(0.2, 3.0, n)
        cols[f"meas_{s}_ms"] = meas
        cols[f"pred_{s}_ms"] = meas * factor[s] * (1 + rng.uniform(-noise, noise, n))
        cols[f"together_{s}_ms"] = np.full(n, 10.0)
    return pd.DataFrame(cols)


def test_a_uniform_drift_is_the_whole_raw_error_and_none_of_the_scaled():
    err = tile_errors(_tiles(dict.fromkeys(STRATEGIES, 0.75)), _model()).set_index("strategy")
    for s in STRATEGIES:
        assert err.loc[s, "median |relative error| %"] == pytest.approx(25.0)
        assert err.loc[s, SCALED] == pytest.approx(0.0, abs=1e-9)
        if s != "raycast":
            assert err.loc[s, "median |relative error| of the ratio to raycast %"] == pytest.approx(0.0, abs=1e-9)
    assert err.loc["all", "median predicted / measured"] == pytest.approx(0.75)


def test_the_scale_leaves_per_tile_scatter():
    err = tile_errors(_tiles(dict.fromkeys(STRATEGIES, 0.75), noise=0.2), _model()).set_index("strategy")
    for s in STRATEGIES:
        assert 7.0 < err.loc[s, SCALED] < 13.0  # |uniform(-0.2, 0.2)| has median 0.1
        assert err.loc[s, "median |relative error| %"] > 20.0


def test_one_scale_for_the_run_does_not_absorb_a_strategy_bias():
    """A model that is right for raster and half for ray casting stays wrong for one of them after the scale."""
    err = tile_errors(_tiles({"raster": 1.0, "raster_gs": 1.0, "raycast": 0.5}), _model()).set_index("strategy")
    assert err.loc["all", "median predicted / measured"] == pytest.approx(1.0, abs=0.02)
    assert err.loc["raycast", SCALED] > 45.0
    assert err.loc["raster", "median |relative error| of the ratio to raycast %"] == pytest.approx(100.0)
