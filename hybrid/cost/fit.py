"""Fitting the cost model: non-negative least squares on relative error, per-frame overheads, held-out error.

The per-tile times are taken inside frames (``Renderer.time_in_frame``), each tile's call paying the
strategy's per-call overhead, which ``estimate_overhead`` recovers from the same frames drawn in one call.
Rows are weighted by 1 / measured time, so small tiles count as much as big ones; the median absolute
relative error is reported on tiles held out of the fit.
"""
from __future__ import annotations

import numpy as np

from hybrid.cost.features import TileFeatures
from hybrid.cost.model import TERMS, CostModel, term_values
from hybrid.cost.nnls import nnls
from hybrid.errors import TerrabenchError


def fit_strategy(features: list[TileFeatures], ms: np.ndarray, strategy: str, overhead: float = 0.0) -> dict:
    """Non-negative per-tile coefficients of one strategy, fitted on the relative error of per-tile times.

    ``ms`` are times of drawing each tile in its own call, so each includes the strategy's per-frame
    ``overhead``, which is taken off before fitting.
    """
    ms = np.asarray(ms, dtype=np.float64)
    if len(features) != len(ms) or len(ms) < len(TERMS[strategy]):
        raise TerrabenchError(f"need at least {len(TERMS[strategy])} timed tiles with matching features to fit "
                              f"{strategy}, got {len(ms)}")
    if not np.all(np.isfinite(ms)) or np.any(ms <= 0):
        raise TerrabenchError("measured times must be finite and > 0 ms")
    A = np.array([term_values(f, strategy) for f in features])
    scale = np.maximum(A.max(axis=0), 1e-12)                 # condition the columns
    w = 1.0 / ms
    x = nnls(A / scale * w[:, None], (ms - overhead) * w) / scale
    return dict(zip(TERMS[strategy], map(float, x)))


def median_rel_error(model: CostModel, features: list[TileFeatures], ms: np.ndarray, strategy: str) -> float:
    """Median |predicted - measured| / measured over per-tile times (overhead included on both sides)."""
    pred = np.array([model.predict(f)[strategy] for f in features]) + model.overhead.get(strategy, 0.0)
    ms = np.asarray(ms, dtype=np.float64)
    return float(np.median(np.abs(pred - ms) / ms))


def estimate_overhead(single_ms: list[np.ndarray], together_ms: list[float]) -> float:
    """Per-frame overhead (ms) from frames timed tile by tile and all at once: (sum of tiles - together) / (k - 1)."""
    est = [(float(np.sum(s)) - t) / (len(s) - 1) for s, t in zip(single_ms, together_ms) if len(s) >= 2]
    return float(max(np.median(est), 0.0)) if est else 0.0


def fit_cost_model(features: list[TileFeatures], times: dict[str, np.ndarray], renderer: str,
                   holdout: float = 0.3, seed: int = 0, overhead: dict | None = None) -> CostModel:
    """Fit every strategy in ``times`` (per-tile ms, one array per candidate; raster and raycast needed) on a
    random (1 - holdout) share of tiles; report errors on the rest.

    ``overhead`` (ms per frame and strategy, see estimate_overhead) is taken off the per-tile times.
    """
    n = len(features)
    times = {s: np.asarray(v, float) for s, v in times.items()}
    for s in ("raster", "raycast"):
        if s not in times:
            raise TerrabenchError(f"cannot fit a cost model without {s} times")
    unknown = sorted(set(times) - set(TERMS))
    if unknown:
        raise TerrabenchError(f"no cost terms for {', '.join(unknown)}; the model knows {', '.join(TERMS)}")
    if not (0.0 <= holdout < 1.0):
        raise TerrabenchError(f"holdout must lie in [0, 1), got {holdout}")
    idx = np.random.default_rng(seed).permutation(n)
    n_test = int(round(holdout * n))
    test, train = idx[:n_test], idx[n_test:]
    ftrain = [features[i] for i in train]
    overhead = {**{s: 0.0 for s in TERMS}, **(overhead or {})}
    coef = {s: fit_strategy(ftrain, ms[train], s, overhead[s]) for s, ms in times.items()}
    model = CostModel(renderer, coef["raster"], coef["raycast"], tiles=n, overhead=overhead,
                      raster_gs=coef.get("raster_gs", {}))
    if n_test:
        ftest = [features[i] for i in test]
        model.fit_error = {s: median_rel_error(model, ftest, ms[test], s) for s, ms in times.items()}
    return model
