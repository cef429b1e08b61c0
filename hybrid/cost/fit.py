"""Fitting the cost model: non-negative least squares on relative error, per-frame overheads, held-out error.

``fit_frames`` (what calibration uses) fits every strategy's coefficients and per-frame overhead together to
whole frames' times: frames drawn one way and frames whose tiles were given to the strategies at random, each
row a frame (its time against, per strategy, whether it is used and the sum of its tiles' terms). A frame
is what the choice must make fast, and on a CPU rasterizer it is not the sum of its tiles drawn one call each
(a call of one tile cannot overlap its vertex and fragment work, nor its fragments with the next tile's): on
Puget the per-tile fit priced raster frames of the orbit 30 % too cheap and of the dolly 25 % too dear. The
random assignments make each strategy's pixels and triangles vary apart from the frame's, which pure frames
alone (every frame about the whole screen) cannot.

Rows are weighted by 1 / measured time, so short frames count as much as long ones; the median absolute relative
error is reported on frames held out of the fit.

Tiles timed inside frames one call each (``Renderer.time_in_frame``: the oracle's measurements) pay the strategy's
per-call overhead, which ``estimate_overhead`` recovers from the same frames drawn in one call.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.cost.model import TERMS, CostModel
from hybrid.cost.nnls import nnls
from hybrid.errors import TerrabenchError


def estimate_overhead(single_ms: list[np.ndarray], together_ms: list[float]) -> float:
    """Per-frame overhead (ms) from frames timed tile by tile and all at once: (sum of tiles - together) / (k - 1)."""
    est = [(float(np.sum(s)) - t) / (len(s) - 1) for s, t in zip(single_ms, together_ms) if len(s) >= 2]
    return float(max(np.median(est), 0.0)) if est else 0.0


@dataclass(frozen=True)
class FrameSample:
    """One whole frame timed: per strategy whether a tile used it and the sum of its tiles' terms
    (``term_values``), and the frame's drawing ms."""

    used: dict
    sums: dict
    ms: float


def frame_design(samples: list[FrameSample], names) -> np.ndarray:
    """(frames, columns) rows of ``fit_frames``: per strategy of ``names``, used (0/1), then its terms' sums."""
    return np.array([np.concatenate([np.r_[float(f.used[s]), np.asarray(f.sums[s], dtype=np.float64)]
                                     for s in names]) for f in samples])


def fit_frames(samples: list[FrameSample], renderer: str, holdout: float = 0.3, seed: int = 0,
               names=("raster", "raster_gs", "raycast")) -> CostModel:
    """Coefficients and per-frame overheads of every strategy in ``names`` fitted together on a random
    (1 - holdout) share of whole frames' times (non-negative, relative error); ``fit_error`` is the held-out median
    relative error of the frames using each strategy."""
    if not (0.0 <= holdout < 1.0):
        raise TerrabenchError(f"holdout must lie in [0, 1), got {holdout}")
    ms = np.array([f.ms for f in samples], dtype=np.float64)
    width = sum(1 + len(TERMS[s]) for s in names)
    if len(samples) < width or not np.all(np.isfinite(ms)) or np.any(ms <= 0):
        raise TerrabenchError(f"need at least {width} frames with finite times > 0 ms to fit {', '.join(names)}, "
                              f"got {len(samples)}")
    X = frame_design(samples, names)
    idx = np.random.default_rng(seed).permutation(len(samples))
    n_test = int(round(holdout * len(samples)))
    test, train = idx[:n_test], idx[n_test:]
    scale = np.maximum(np.abs(X[train]).max(axis=0), 1e-12)
    w = 1.0 / ms[train]
    x = nnls(X[train] / scale * w[:, None], ms[train] * w) / scale
    coef, overhead, i = {}, {s: 0.0 for s in TERMS}, 0
    for s in names:
        overhead[s] = float(x[i])
        coef[s] = dict(zip(TERMS[s], map(float, x[i + 1:i + 1 + len(TERMS[s])])))
        i += 1 + len(TERMS[s])
    model = CostModel(renderer, coef["raster"], coef["raycast"], overhead=overhead, raster_gs=coef.get("raster_gs", {}),
                      frames=len(samples))
    if n_test:
        err = np.abs(X[test] @ x - ms[test]) / ms[test]
        used = X[test][:, np.cumsum([0] + [1 + len(TERMS[s]) for s in names])[:-1]] > 0
        model.fit_error = {s: float(np.median(err[used[:, j]])) for j, s in enumerate(names) if used[:, j].any()}
    return model
