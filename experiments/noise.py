"""Timing comparisons that tell findings from noise, from the repeats of one run.

Every frame of a configuration is timed ``repeats`` times (``wall_ms_repeats``; its median is ``wall_ms``), and
methods render the same frames (paired views). A method's time over a flight is the median over frames of the
per-frame medians. Two measures of noise come from the same run:

- the bootstrap interval (95 %) of the ratio of two methods' times, resampling frames (paired) and, within
  each drawn frame, its repeats, as the estimate itself is made;
- the repeat spread: per frame (max - min) / median of its repeats, the median over the frames.

A difference is within noise (a tie) when the interval holds 1 or the ratio differs from 1 by less than the
larger repeat spread of the two methods: what the same frame varies by when drawn again is not a finding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

BOOTSTRAP = 2000  # bootstrap resamples
LEVEL = 0.95  # two-sided interval


def repeat_matrix(g: pd.DataFrame) -> np.ndarray:
    """Frame times (frames x repeats, ms, in frame order) of one method; rows from ``wall_ms_repeats`` where every
    frame has the same number of repeats, else one column of the per-frame medians (older runs)."""
    g = g.sort_values("frame")
    if "wall_ms_repeats" in g:
        reps = [np.asarray(r, dtype=np.float64) for r in g["wall_ms_repeats"] if r is not None and np.size(r) > 0]
        if len(reps) == len(g) and len({len(r) for r in reps}) == 1:
            return np.stack(reps)
    return g["wall_ms"].to_numpy(np.float64)[:, None]


def repeat_spread(times: np.ndarray) -> float:
    """Median over frames of (max - min) / median of a frame's repeats (0 with one repeat)."""
    med = np.median(times, axis=1)
    return float(np.median((times.max(axis=1) - times.min(axis=1)) / med))


def flight_ms(times: np.ndarray) -> float:
    """A method's time over a flight: the median over frames of the per-frame medians of repeats (ms)."""
    return float(np.median(np.median(times, axis=1)))


def _resampled_ms(times: np.ndarray, frames: np.ndarray, rng) -> np.ndarray:
    """flight_ms of each bootstrap draw: frames (B x n indices) and, per drawn frame, repeats with replacement."""
    r = times.shape[1]
    reps = rng.integers(0, r, frames.shape + (r,))
    per_frame = np.median(times[frames[..., None], reps], axis=2)
    return np.median(per_frame, axis=1)


def median_interval(times: np.ndarray, seed: int = 0) -> tuple[float, float]:
    """Bootstrap interval (LEVEL) of flight_ms (ms), resampling frames and repeats."""
    rng = np.random.default_rng(seed)
    frames = rng.integers(0, len(times), (BOOTSTRAP, len(times)))
    ms = _resampled_ms(times, frames, rng)
    q = (1 - LEVEL) / 2
    return float(np.quantile(ms, q)), float(np.quantile(ms, 1 - q))


@dataclass
class Comparison:
    """Method a against method b over the frames both rendered: times (ms), ratio a / b with its bootstrap
    interval, and the larger repeat spread of the two (relative)."""

    a: str
    b: str
    ms_a: float
    ms_b: float
    ratio: float
    low: float
    high: float
    spread: float

    @property
    def tie(self) -> bool:
        """Within noise: the interval holds 1, or the ratio is within the repeat spread of 1."""
        return self.low <= 1.0 <= self.high or abs(self.ratio - 1.0) <= self.spread

    def words(self) -> str:
        """'within noise' or 'N.NNx faster/slower' for a against b, with the interval."""
        if self.tie:
            return (
                f"within noise (ratio {self.ratio:.2f}, interval {self.low:.2f}-{self.high:.2f}, "
                f"repeats spread {100 * self.spread:.0f} %)"
            )
        if self.ratio < 1:
            return f"{1 / self.ratio:.2f}x faster (interval {1 / self.high:.2f}-{1 / self.low:.2f}x)"
        return f"{self.ratio:.2f}x slower (interval {self.low:.2f}-{self.high:.2f}x)"


def compare(a: str, ga: pd.DataFrame, b: str, gb: pd.DataFrame, seed: int = 0) -> Comparison:
    """Compare the frame times of method a (rows ga) with method b (rows gb) over the frames both rendered."""
    common = sorted(set(ga["frame"]) & set(gb["frame"]))
    ta = repeat_matrix(ga[ga["frame"].isin(common)])
    tb = repeat_matrix(gb[gb["frame"].isin(common)])
    ms_a, ms_b = flight_ms(ta), flight_ms(tb)
    rng = np.random.default_rng(seed)
    frames = rng.integers(0, len(common), (BOOTSTRAP, len(common)))
    ratios = _resampled_ms(ta, frames, rng) / _resampled_ms(tb, frames, rng)
    q = (1 - LEVEL) / 2
    return Comparison(
        a,
        b,
        ms_a,
        ms_b,
        ms_a / ms_b,
        float(np.quantile(ratios, q)),
        float(np.quantile(ratios, 1 - q)),
        max(repeat_spread(ta), repeat_spread(tb)),
    )
