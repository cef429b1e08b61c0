"""Fitting the cost model: non-negative least squares on relative error, per-frame overheads, held-out error.

``fit_frames`` (what calibration uses) fits every strategy's coefficients and per-frame overhead together to
whole frames' times: frames drawn one way and frames whose tiles were given to the strategies at random, each
row a frame (its time against, per strategy, whether it is used and the sum of its tiles' terms, and whether it
uses more than one: a mixed frame's own overhead, ``CostModel.mix_overhead``). A frame
is what the choice must make fast, and on a CPU rasterizer it is not the sum of its tiles drawn one call each
(a call of one tile cannot overlap its vertex and fragment work, nor its fragments with the next tile's): on
Puget the per-tile fit priced raster frames of the orbit 30 % too cheap and of the dolly 25 % too dear. The
random assignments make each strategy's pixels and triangles vary apart from the frame's, which pure frames
alone (every frame about the whole screen) cannot.

Tiles timed inside frames one call each (``Renderer.time_in_frame``: the oracle's measurements) join the fit as
rows of their own: the same coefficients, plus a per-call overhead of each strategy (what drawing one tile as its
own call adds), fitted with them. The tiles' rows weigh as much in all as the frames' (``TILE_WEIGHT``): the
frames say what a whole frame costs, the tiles what each tile adds to it, whose terms vary apart from one
another far more than a frame's sums do; held out, both errors are reported.

Rows are weighted by 1 / measured time, so short frames count as much as long ones; the median absolute relative
error is reported on frames (and tiles) held out of the fit.

``estimate_overhead`` recovers a per-call overhead from frames timed tile by tile and in one call (the oracle's).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls

from hybrid.cost.model import TERMS, CostModel
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


TILE_WEIGHT = 1.0
"""The tiles' rows' weight in the joint fit against the frames' (each set's squared weights summed). Two llvmpipe
calibrations of Puget (the shipped settings), each fitted over 8 hold-out draws: at 0.3 the held-out per-tile
errors were 13-20 % and the frames' 8-9 %, the ray caster's pixel coefficient 0 in one and 1.9e-5 +- 2.3e-5 ms
in the other, and the mixed frame's overhead 0-0.8 ms; at 1.0 the tiles' 13-17 %, the frames' 9-11 %, each
per-tile coefficient within 16 % between the two (or near 0 in both), and mixed frames 0.8-2.7 ms dearer than
their tiles and strategies (priced tiles pin what the frames' excess is; the per-frame overheads still differ,
ray casting 3.7 and 5.4 ms); at 2.0 the frames' rose to 10-13 %."""


@dataclass(frozen=True)
class TileSample:
    """One tile drawn as one call inside a frame and timed: its strategy, its terms (``term_values``) and ms."""

    strategy: str
    terms: np.ndarray
    ms: float


def frame_design(samples: list[FrameSample], names) -> np.ndarray:
    """(frames, columns) rows of ``fit_frames``: per strategy of ``names``, used (0/1), then its terms' sums; last,
    mixed (1 where the frame uses more than one strategy of ``names``)."""
    return np.array(
        [
            np.concatenate(
                [np.r_[float(f.used[s]), np.asarray(f.sums[s], dtype=np.float64)] for s in names]
                + [[float(sum(bool(f.used[s]) for s in names) > 1)]]
            )
            for f in samples
        ]
    )


def fit_frames(
    samples: list[FrameSample],
    renderer: str,
    holdout: float = 0.3,
    seed: int = 0,
    names=("raster", "raster_gs", "raycast"),
    tiles: Sequence[TileSample] = (),
) -> CostModel:
    """Coefficients and per-frame overheads of every strategy in ``names``, and the overhead of a frame that mixes
    strategies (``mix_overhead``), fitted together on a random
    (1 - holdout) share of whole frames' times (non-negative, relative error); ``fit_error`` is the held-out median
    relative error of the frames using each strategy, ``mix_error`` that of the frames using more than one. With
    ``tiles`` (timed one call each), a random (1 - holdout) share of them joins the fit with a per-call overhead
    per strategy (``call_overhead``), and ``tile_error`` is the held-out median relative error of the rest per
    strategy."""
    width = sum(1 + len(TERMS[s]) for s in names) + 1  # the strategies' columns, then mixed
    tiles = [t for t in tiles if t.strategy in names]
    ms, tms = _checked_times(samples, tiles, names, width, holdout)
    offsets = np.cumsum([0] + [1 + len(TERMS[s]) for s in names])
    calls = len(names) if tiles else 0
    X = np.hstack([frame_design(samples, names), np.zeros((len(samples), calls))])
    T = _tile_design(tiles, names, offsets, width + calls)
    rng = np.random.default_rng(seed)
    test, train = _split(rng, len(samples), holdout)
    t_test, t_train = _split(rng, len(tiles), holdout)
    rows, b = [X[train] / ms[train, None]], [np.ones(len(train))]
    if len(t_train):  # the tiles' rows weigh TILE_WEIGHT of the frames' in all
        k = TILE_WEIGHT * np.sqrt(len(train) / len(t_train))
        rows.append(k * T[t_train] / tms[t_train, None])
        b.append(np.full(len(t_train), k))
    A = np.vstack(rows)
    scale = np.maximum(np.abs(A).max(axis=0), 1e-12)
    x = nnls(A / scale, np.concatenate(b), maxiter=50 * A.shape[1])[0] / scale
    coef, overhead = {}, dict.fromkeys(TERMS, 0.0)
    for j, s in enumerate(names):
        overhead[s] = float(x[offsets[j]])
        coef[s] = dict(zip(TERMS[s], map(float, x[offsets[j] + 1 : offsets[j + 1]])))
    model = CostModel(
        renderer,
        coef,
        overhead=overhead,
        frames=len(samples),
        tiles=len(tiles),
        mix_overhead=float(x[width - 1]),
    )
    if calls:
        model.call_overhead = {s: float(x[width + j]) for j, s in enumerate(names)}
    if len(test):
        _held_out_frame_errors(model, X[test] @ x, ms[test], X[test][:, offsets[:-1]] > 0, names)
    if len(t_test):
        err = np.abs(T[t_test] @ x - tms[t_test]) / tms[t_test]
        which = np.array([names.index(tiles[i].strategy) for i in t_test])
        model.tile_error = {s: float(np.median(err[which == j])) for j, s in enumerate(names) if (which == j).any()}
    return model


def _checked_times(samples: list, tiles: list, names: tuple, width: int, holdout: float) -> tuple:
    """Measured ms of the frames and of the tiles (float64 arrays), refused by name where too few, not finite or
    not positive, or where the held-out share is outside [0, 1)."""
    if not (0.0 <= holdout < 1.0):
        raise TerrabenchError(f"holdout must lie in [0, 1), got {holdout}")
    ms = np.array([f.ms for f in samples], dtype=np.float64)
    if len(samples) < width or not np.all(np.isfinite(ms)) or np.any(ms <= 0):
        raise TerrabenchError(
            f"need at least {width} frames with finite times > 0 ms to fit {', '.join(names)}, got {len(samples)}"
        )
    tms = np.array([t.ms for t in tiles], dtype=np.float64)
    if not np.all(np.isfinite(tms)) or np.any(tms <= 0):
        raise TerrabenchError("tiles timed one call each need finite times > 0 ms")
    return ms, tms


def _tile_design(tiles: list, names: tuple, offsets: np.ndarray, width: int) -> np.ndarray:
    """Rows (tiles, width) of tiles timed one call each: each tile's terms in its strategy's columns and a 1 in
    its strategy's per-call column (the last ``len(names)`` columns)."""
    T = np.zeros((len(tiles), width))
    for k, t in enumerate(tiles):
        j = names.index(t.strategy)
        T[k, offsets[j] + 1 : offsets[j + 1]] = t.terms
        T[k, width - len(names) + j] = 1.0
    return T


def _held_out_frame_errors(
    model: CostModel, predicted: np.ndarray, ms: np.ndarray, used: np.ndarray, names: tuple
) -> None:
    """Set the model's held-out median relative frame error per strategy (frames using it: ``used`` (F, S)) and
    that of the frames mixing strategies, from predicted and measured frame ms (F,)."""
    err = np.abs(predicted - ms) / ms
    model.fit_error = {s: float(np.median(err[used[:, j]])) for j, s in enumerate(names) if used[:, j].any()}
    mixed = used.sum(axis=1) > 1
    model.mix_error = float(np.median(err[mixed])) if mixed.any() else 0.0


def _split(rng, n: int, holdout: float) -> tuple[np.ndarray, np.ndarray]:
    """(held out, fitted) indices of n rows, a random ``holdout`` share held out."""
    idx = rng.permutation(n)
    k = int(round(holdout * n))
    return idx[:k], idx[k:]
