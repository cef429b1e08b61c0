"""The cheapest assignment of tiles to strategies under per-tile costs and per-strategy frame overheads.

A frame that uses a set S of strategies costs sum over s in S of overhead_s plus each tile's cost under the
strategy it is given. For a fixed S every tile takes its cheapest strategy in S, so trying every non-empty S
(7 sets for three candidates) finds the optimum exactly. Both the hybrid (predicted costs) and the oracle
(costs measured inside frames) choose this way; a pure set may be priced by a measured whole-frame time.
"""
from __future__ import annotations

import functools
import itertools

import numpy as np


@functools.lru_cache(maxsize=None)
def _subsets(s: int) -> np.ndarray:
    """(2^s - 1, s) masks of the non-empty subsets of s strategies, smaller sets first (itertools order)."""
    rows = [np.isin(np.arange(s), c) for k in range(1, s + 1) for c in itertools.combinations(range(s), k)]
    return np.array(rows, dtype=bool).reshape(-1, s)


def best_assignment(costs: dict[str, np.ndarray], overhead: dict[str, float],
                    pure_ms: dict[str, float] | None = None) -> tuple[list[str], float]:
    """(strategy per tile, frame ms) of the cheapest assignment; ``costs`` are per-tile ms ((B,) arrays, overhead
    excluded), ``overhead`` ms per frame per strategy used, ``pure_ms`` a measured frame time that replaces the
    sum for a one-strategy frame. Ties go to the earlier strategy in ``costs`` and to fewer strategies.

    Every subset is priced at once: (subsets, strategies, tiles) costs with the strategies outside a subset
    at infinity."""
    names = list(costs)
    table = np.stack([np.asarray(costs[n], dtype=np.float64) for n in names])       # (S, B)
    n_tiles = table.shape[1]
    masks = _subsets(len(names))                                                     # (K, S)
    if n_tiles == 0:
        pick = np.zeros((len(masks), 0), dtype=np.int64)
        used = masks & (np.cumsum(masks, axis=1) == 1)                              # a frame of nothing: first only
    else:
        priced = np.where(masks[:, :, None], table[None], np.inf)                   # (K, S, B)
        pick = np.argmin(priced, axis=1)                                             # (K, B), first on ties
        used = (pick[:, None, :] == np.arange(len(names))[None, :, None]).any(axis=2)   # (K, S)
    fits = used.sum(axis=1) == masks.sum(axis=1)        # a subset some strategy of which is unused: priced smaller
    tiles = table[pick, np.arange(n_tiles)].sum(axis=1) if n_tiles else np.zeros(len(masks))
    total = tiles + used.astype(np.float64) @ np.array([overhead.get(n, 0.0) for n in names])
    if pure_ms:
        single = masks.sum(axis=1) == 1
        for i, n in enumerate(names):
            if n in pure_ms:
                total[single & masks[:, i]] = float(pure_ms[n])
    total = np.where(fits, total, np.inf)
    k = int(np.argmax(total <= total.min() + 1e-12))                                 # the first of the cheapest
    return [names[i] for i in pick[k].tolist()], float(total[k])
