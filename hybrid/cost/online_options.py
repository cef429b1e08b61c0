"""Plain data of online adaptation (``hybrid.cost.online``): its options, an exploration of one frame, and what it
did over a renderer's life."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hybrid.errors import TerrabenchError


@dataclass(frozen=True)
class AdaptOptions:
    """How the hybrid's cost model adapts online: rows kept, the ridge toward the starting model, the exploration
    budget (share of frame time), when a strategy's predictions hold and the rows a strategy needs before its own
    level replaces the machine's (``level_rows``)."""

    window: int = 48
    prior_weight: float = 2.0
    prior_share: float = 0.5
    explore_share: float = 0.05
    explore_tiles: int = 2
    hold_rows: int = 6
    level_rows: int = 3
    hold_error: float = 0.15
    refit_every: int = 8

    def __post_init__(self):
        counts = (self.hold_rows, self.level_rows, self.explore_tiles, self.refit_every)
        if not (self.window >= 4 and min(counts) >= 1):
            raise TerrabenchError(
                "adapt options need window >= 4 and hold_rows, level_rows, explore_tiles, refit_every >= 1"
            )
        for name in ("prior_weight", "prior_share", "explore_share", "hold_error"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise TerrabenchError(f"adapt option {name} must be a finite number >= 0, got {v!r}")


@dataclass
class Exploration:
    """Tiles of one frame given to a strategy to learn it: their indices, the predicted ms the chosen
    strategies would have drawn them in, and whether the frame as chosen used one strategy."""

    strategy: str
    tiles: np.ndarray
    base_ms: float
    pure: bool = True


@dataclass
class AdaptStats:
    """What adaptation did over a renderer's life: frames observed, refits, exploration (frames, tiles, measured
    ms) against all observed frames' ms."""

    frames: int = 0
    refits: int = 0
    explored_frames: int = 0
    explored_tiles: int = 0
    explore_ms: float = 0.0
    frame_ms: float = 0.0
    errors: dict = field(default_factory=dict)

    @property
    def explore_share(self) -> float:
        """Measured exploration cost as a share of the observed frames' time."""
        return self.explore_ms / self.frame_ms if self.frame_ms > 0 else 0.0
