"""The online fit of one strategy's rows (``hybrid.cost.online``), kept in a ring (``RowWindow``): non-negative
least squares on relative error with a ridge toward the starting model, and, while most of its passes drew a few
explored tiles, a split that takes their level from the passes of many tiles and their per-frame overhead from
the rest."""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls


def median_of(values) -> float:
    """Median of a short sequence (numpy's median costs more than the sort on a few dozen values)."""
    v = sorted(values)
    n = len(v)
    return float(v[n // 2]) if n % 2 else 0.5 * float(v[n // 2 - 1] + v[n // 2])


OUTLIER = 4.0
"""Rows whose relative residual is over this many times the median one (and over 0.25) are refitted without."""


def fit_rows(
    X: np.ndarray,
    y: np.ndarray,
    prior: np.ndarray,
    prior_weight: float,
    prior_share: float = 0.0,
    shape_rows: int = 0,
    few_tiles: int = 0,
    own_level: bool = True,
) -> np.ndarray:
    """Non-negative [overhead, coefficients] of one strategy from rows of terms X (n, p; column 1 the tile
    count) and measured ms y (n,), on relative error, with a ridge toward ``prior`` scaled by the rows' median
    measured / predicted, worth the larger of ``prior_weight`` rows and ``prior_share`` of the rows; outliers
    (``OUTLIER``) dropped and refitted once. No rows: the prior. Fewer than ``shape_rows`` rows of more than
    ``few_tiles`` tiles: ``few_tile_fit`` (passes of a few explored tiles tell a strategy's per-frame overhead
    more than its tiles' cost). Without ``own_level``: the prior as given (a strategy of too
    few rows to tell its own level follows the machine's, which the caller has applied)."""
    if len(y) == 0 or not own_level:
        return prior.copy()
    if int(np.count_nonzero(X[:, 1] > few_tiles)) < shape_rows:
        return few_tile_fit(X, y, prior, few_tiles)
    pred = X @ prior
    ratio = y[pred > 0] / pred[pred > 0]
    scaled = prior * (median_of(ratio.tolist()) if len(ratio) else 1.0)
    A = X / y[:, None]
    col = np.sqrt(np.einsum("ij,ij->j", A, A) / len(y))
    col = np.where(col > 0, col, 1.0)
    keep = np.ones(len(y), dtype=bool)
    for _ in range(2):
        ridge = np.sqrt(max(prior_weight, prior_share * int(keep.sum()))) * np.eye(len(prior))
        M = np.vstack([A[keep] / col, ridge])
        b = np.concatenate([np.ones(int(keep.sum())), ridge @ (scaled * col)])
        u, _ = nnls(M, b, maxiter=50 * len(prior))
        theta = u / col
        res = np.abs(A @ theta - 1.0)
        cut = max(OUTLIER * median_of(res.tolist()), 0.25)
        if keep.sum() < 4 or np.all(res[keep] <= cut):
            break
        keep = res <= cut
    return theta


def few_tile_fit(X: np.ndarray, y: np.ndarray, prior: np.ndarray, few_tiles: int) -> np.ndarray:
    """[overhead, coefficients] of a strategy whose passes mostly drew ``few_tiles`` tiles or fewer: its per-tile
    coefficients are the prior's at the level of its passes of more tiles (their measured / predicted ms, summed, so
    that the costly passes weigh most), else at the median level of its passes; its overhead is what the passes
    measured beyond their tiles (median, >= 0). A pass of two explored tiles is mostly the strategy's per-frame
    work: once the strategy drew a frame's tiles whole, that pass, not the many small ones, prices its tiles."""
    many = X[:, 1] > few_tiles
    pred = X @ prior
    if many.any() and pred[many].sum() > 0:
        level = float(y[many].sum() / pred[many].sum())
    else:
        ok = pred > 0
        level = median_of((y[ok] / pred[ok]).tolist()) if ok.any() else 1.0
    tiles = prior[1:] * level
    overhead = max(median_of((y - X[:, 1:] @ tiles).tolist()), 0.0)
    return np.concatenate([[overhead], tiles])


class RowWindow:
    """The last ``size`` rows of one strategy: terms (size, width) and measured ms (size,), in a ring."""

    def __init__(self, size: int, width: int):
        self.X = np.zeros((size, width))
        self.y = np.zeros(size)
        self.n = 0

    def add(self, x: np.ndarray, ms: float) -> None:
        """Keep a row, dropping the oldest once full."""
        i = self.n % len(self.y)
        self.X[i], self.y[i] = x, ms
        self.n += 1

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(terms, ms) of the rows kept (order not kept)."""
        k = min(self.n, len(self.y))
        return self.X[:k], self.y[:k]

    def __len__(self) -> int:
        return min(self.n, len(self.y))
