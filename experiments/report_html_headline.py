"""The HTML report's headline per scene: the fastest method (with the ones within noise of it), the hybrid's gain
over the better pure method at the same tau (with its bootstrap interval), and the most accurate method.

Rows are chosen as ``experiments.reading.mixed_sentences`` chooses them, and timings go through
``experiments.noise.compare``, so the headline and the reading agree on every number and every tie.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

from .charts import label_columns
from .noise import Comparison, compare

PURE = ("raster", "raster_gs", "raycast")


@dataclass
class Gain:
    """One hybrid method against the faster pure method at its tau (``cmp``: hybrid over pure)."""

    hybrid: str
    pure: str
    cmp: Comparison

    @property
    def verdict(self) -> str:
        """'win', 'tie' or 'loss' for the hybrid."""
        return "tie" if self.cmp.tie else "win" if self.cmp.ratio < 1 else "loss"

    def words(self) -> str:
        """The gain in a few words: 'N.NN× faster (interval a–b×)', slower likewise, or within noise."""
        c = self.cmp
        if c.tie:
            return f"within noise (ratio {c.ratio:.2f}, interval {c.low:.2f}–{c.high:.2f})"
        if c.ratio < 1:
            return f"{1 / c.ratio:.2f}× faster (interval {1 / c.high:.2f}–{1 / c.low:.2f}×)"
        return f"{c.ratio:.2f}× slower (interval {c.low:.2f}–{c.high:.2f}×)"


@dataclass
class SceneHeadline:
    """What a reader wants first of a scene."""

    scene: str
    fastest: str
    fastest_ms: float
    tied: list[tuple[str, float]] = field(default_factory=list)  # within noise of the fastest
    gains: list[Gain] = field(default_factory=list)
    accurate: list[str] = field(default_factory=list)  # lowest mean FLIP (equal values together)
    flip: float | None = None


def _pure_rows(g: pd.DataFrame, sub: pd.DataFrame, tau, rec, fr) -> dict[str, pd.DataFrame]:
    """The pure methods' rows that a mixed policy of (tau, rec, fr) is compared with, as the reading picks them:
    raster drawn once with the first reconstruction, ray casting once with the exact full-resolution rule."""
    pure = {p: sub[sub["policy"] == p] for p in PURE}
    for p in PURE:
        if pure[p].empty:
            same = (g["policy"] == p) & (g["tau"] == tau)
            pure[p] = g[same & (g["full_res"] == fr)] if p != "raycast" else g[same & (g["reconstruction"] == rec)]
    return {p: r for p, r in pure.items() if not r.empty}


def hybrid_gains(g: pd.DataFrame) -> list[Gain]:
    """Each hybrid method of a scene (labelled frames) against the faster pure method at its tau."""
    out = []
    for (tau, rec, fr), sub in g.groupby(["tau", "reconstruction", "full_res"]):
        pure = _pure_rows(g, sub, tau, rec, fr)
        if not pure:
            continue
        best = min(pure, key=lambda p: pure[p]["wall_ms"].median())
        ref = pure[best]
        for name in sorted(sub.loc[sub["policy"] == "hybrid", "method"].unique()):
            rows = sub[sub["method"] == name]
            out.append(Gain(name, ref["method"].iloc[0], compare(name, rows, ref["method"].iloc[0], ref)))
    return out


def _fastest(g: pd.DataFrame) -> tuple[str, float, list[tuple[str, float]]]:
    """The method with the lowest median frame time and the methods within noise of it."""
    ms = g.groupby("method")["wall_ms"].median().sort_values()
    first = ms.index[0]
    best = g[g["method"] == first]
    tied = [(m, float(ms[m])) for m in ms.index[1:] if compare(m, g[g["method"] == m], first, best).tie]
    return first, float(ms[first]), tied


def scene_headlines(frames: pd.DataFrame) -> list[SceneHeadline]:
    """The headline of every scene of a run's frames table, in scene order."""
    f = label_columns(frames)
    out = []
    for sc, g in f.groupby("scene"):
        first, ms, tied = _fastest(g)
        h = SceneHeadline(str(sc), first, ms, tied, hybrid_gains(g))
        if "flip" in g and g["flip"].notna().any():
            acc = g.groupby("method")["flip"].mean().round(5).dropna().sort_values()
            h.accurate, h.flip = acc[acc == acc.iloc[0]].index.tolist(), float(acc.iloc[0])
        out.append(h)
    return out
