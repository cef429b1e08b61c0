"""The cheapest assignment of tiles to strategies under per-tile costs and per-strategy frame overheads.

A frame that uses a set S of strategies costs sum over s in S of overhead_s, plus a mixed frame's own overhead
where S has more than one, plus each tile's cost under the strategy it is given. For a fixed S every tile takes
its cheapest strategy in S, so trying every non-empty S (7 sets for three candidates) finds the optimum exactly.
Both the hybrid (predicted costs) and the oracle (costs measured inside frames) choose this way; a pure set may
be priced by a measured whole-frame time.
"""

from __future__ import annotations

import functools
import itertools

import numpy as np


@functools.cache
def _subsets(s: int) -> np.ndarray:
    """(2^s - 1, s) masks of the non-empty subsets of s strategies, smaller sets first (itertools order)."""
    rows = [np.isin(np.arange(s), c) for k in range(1, s + 1) for c in itertools.combinations(range(s), k)]
    return np.array(rows, dtype=bool).reshape(-1, s)


def subset_masks(s: int) -> np.ndarray:
    """(2^s - 1, s) masks of the non-empty subsets of s strategies, in the order the assignment prices them."""
    return _subsets(s)


@functools.cache
def _sizes(s: int) -> np.ndarray:
    """(2^s - 1,) strategies in each subset of ``_subsets(s)``."""
    return _subsets(s).sum(axis=1)


def best_assignment(
    costs: dict[str, np.ndarray],
    overhead: dict[str, float],
    pure_ms: dict[str, float] | None = None,
    mixed: float = 0.0,
) -> tuple[list[str], float]:
    """(strategy per tile, frame ms) of the cheapest assignment; ``costs`` are per-tile ms ((B,) arrays, overhead
    excluded), ``overhead`` ms per frame per strategy used, ``pure_ms`` a measured frame time that replaces the
    sum for a one-strategy frame, ``mixed`` ms a frame using more than one strategy adds. Ties go to the earlier
    strategy in ``costs`` and to fewer strategies."""
    names = list(costs)
    table = np.array([np.asarray(costs[n], dtype=np.float64) for n in names], dtype=np.float64).reshape(len(names), -1)
    pure = None if not pure_ms else np.array([pure_ms.get(n, np.nan) for n in names], dtype=np.float64)
    pick, total = best_assignment_table(
        table, np.array([overhead.get(n, 0.0) for n in names], dtype=np.float64), pure, mixed
    )
    return [names[i] for i in pick.tolist()], total


def best_assignment_table(
    table: np.ndarray, overhead: np.ndarray, pure_ms: np.ndarray | None = None, mixed: float = 0.0
) -> tuple[np.ndarray, float]:
    """(strategy index per tile (B,), frame ms) of the cheapest assignment of an (S, B) table of per-tile ms under
    (S,) per-frame overheads; ``pure_ms`` (S,) measured one-strategy frame times (NaN: the sum), ``mixed`` ms added
    to a frame of more than one strategy, as ``best_assignment``.

    Every subset is priced at once: (subsets, strategies, tiles) costs with the strategies outside a subset
    at infinity."""
    s, n_tiles = table.shape
    masks = _subsets(s)  # (K, S)
    if n_tiles == 0:
        pick = np.zeros((len(masks), 0), dtype=np.int64)
        used = masks & (np.cumsum(masks, axis=1) == 1)  # a frame of nothing: first only
        tiles = np.zeros(len(masks))
    else:
        priced = np.where(masks[:, :, None], table, np.inf)  # (K, S, B)
        pick = priced.argmin(axis=1)  # (K, B), first on ties
        used = np.zeros(masks.shape, bool)  # (K, S)
        used[np.arange(len(masks))[:, None], pick] = True
        tiles = priced.min(axis=1).sum(axis=1)
    total = tiles + np.where(used, overhead, 0.0).sum(axis=1) + mixed * (_sizes(s) > 1)
    if pure_ms is not None:
        measured = ~np.isnan(pure_ms)  # the first s subsets are the one-strategy ones, in order
        total[:s][measured] = pure_ms[measured]
    total[used.sum(axis=1) != _sizes(s)] = np.inf  # a subset some strategy of which is unused: priced smaller
    k = int((total <= total.min() + 1e-12).argmax())  # the first of the cheapest
    return pick[k], float(total[k])
