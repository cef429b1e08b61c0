"""The cheapest assignment of tiles to strategies under per-tile costs and per-strategy frame overheads.

A frame that uses a set S of strategies costs sum over s in S of overhead_s plus each tile's cost under the
strategy it is given. For a fixed S every tile takes its cheapest strategy in S, so trying every non-empty S
(7 sets for three candidates) finds the optimum exactly. Both the hybrid (predicted costs) and the oracle
(costs measured inside frames) choose this way; a pure set may be priced by a measured whole-frame time.
"""
from __future__ import annotations

import itertools

import numpy as np


def best_assignment(costs: dict[str, np.ndarray], overhead: dict[str, float],
                    pure_ms: dict[str, float] | None = None) -> tuple[list[str], float]:
    """(strategy per tile, frame ms) of the cheapest assignment; ``costs`` are per-tile ms ((B,) arrays, overhead
    excluded), ``overhead`` ms per frame per strategy used, ``pure_ms`` a measured frame time that replaces the
    sum for a one-strategy frame. Ties go to the earlier strategy in ``costs`` and to fewer strategies."""
    names = list(costs)
    table = np.stack([np.asarray(costs[n], dtype=np.float64) for n in names])       # (S, B)
    n_tiles = table.shape[1]
    best: tuple[float, list[str]] | None = None
    for size in range(1, len(names) + 1):
        for subset in itertools.combinations(range(len(names)), size):
            sub = table[list(subset)]
            pick = np.argmin(sub, axis=0)
            used = sorted({subset[i] for i in pick.tolist()}) if n_tiles else [subset[0]]
            if len(used) < size:
                continue                      # the same frame as a smaller set, already priced
            if size == 1 and pure_ms and names[subset[0]] in pure_ms:
                total = float(pure_ms[names[subset[0]]])
            else:
                total = float(sub[pick, np.arange(n_tiles)].sum()) + sum(overhead.get(names[i], 0.0) for i in used)
            if best is None or total < best[0] - 1e-12:
                best = (total, [names[subset[i]] for i in pick.tolist()] if n_tiles else [])
    assert best is not None
    return best[1], best[0]
