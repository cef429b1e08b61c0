"""The seams of a periodic extension (``hybrid.tiles.periodic``): the source's samples along them and their steps,
and reductions of those profiles over each span of a level's tiles or nodes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .subsampling import block_reduce


def profile_spans(profile: np.ndarray, span: int, fn) -> np.ndarray:
    """fn over each span of a (P + 1,) profile, both ends included: (P / span,)."""
    blocks = block_reduce(profile[None, :-1], span, fn)[0]
    ends = profile[span::span]
    return fn(blocks, ends)


@dataclass(frozen=True)
class SeamProfiles:
    """The source's samples along the extension's seams (metres, float64, P + 1 each, index t of a period): the
    extension's seam row ``row0[t] = h(0, t mod P)`` and seam column ``col0[t] = h(t mod P, 0)``, and their steps
    from the source's last row and column: ``row_step[t] = |h(P, t) - row0[t]|``,
    ``col_step[t] = |h(t, P) - col0[t]|``."""

    row0: np.ndarray
    col0: np.ndarray
    row_step: np.ndarray
    col_step: np.ndarray


def seam_profiles(heights, P: int) -> SeamProfiles:
    """The seam profiles (metres) of a square source grid of P + 1 samples a side (read: two rows, two columns)."""
    wrap = np.arange(P + 1) % P
    row0 = np.asarray(heights[0, :], dtype=np.float64)[wrap]
    col0 = np.asarray(heights[:, 0], dtype=np.float64)[wrap]
    last_row = np.asarray(heights[P, :], dtype=np.float64)
    last_col = np.asarray(heights[:, P], dtype=np.float64)
    return SeamProfiles(row0, col0, np.abs(last_row - row0), np.abs(last_col - col0))
