"""Reusing a clear choice: the hybrid plans in full only every few frames while its choice is one strategy by a wide
margin.

Planning a mixed policy's frame costs CPU time a pure method does not pay (the triangle estimate, features,
predictions, the hedged choice, and an adapting model's bookkeeping). Where the model gives every tile to one
strategy and no other would come near paying its per-frame overhead, that work buys nothing: the next frames
of a flight, a few metres on, choose the same. So after such a frame the next ``frames - 1`` frames are planned
as that pure strategy (tile selection only) and the one after in full again. A choice is clear where drawing any
other strategy's cheaper tiles, at the hedged prices, falls short of its overhead by at least ``slack`` of the
predicted pure frame (``hybrid.cost.planner.pure_slack``). A frame that mixes, explores or streams is never
followed by reuse, nor is one of an adapting model until the chosen strategy's predictions hold: reused frames
give the model no rows. Another strategy still to be learned is explored in the full plans between reuses.
"""

from __future__ import annotations

from dataclasses import dataclass

from hybrid.errors import TerrabenchError

REUSE_FRAMES = 4
"""By default a clear choice is planned in full at least every fourth frame."""


@dataclass
class ChoiceReuse:
    """When a hybrid renderer may draw a frame as its last clear pure choice without planning it (``frames``: a full
    plan at least every that many frames, 1 plans every frame; ``slack``: the share of the predicted pure frame by
    which every other strategy must fall short)."""

    frames: int = REUSE_FRAMES
    slack: float = 0.1
    base: str | None = None
    left: int = 0
    reused: bool = False  # whether the last ``take`` gave a strategy

    def __post_init__(self):
        if not (isinstance(self.frames, int) and self.frames >= 1 and self.slack >= 0):
            raise TerrabenchError(f"choice reuse needs frames >= 1 and slack >= 0, got {self.frames}, {self.slack}")

    def take(self) -> str | None:
        """The strategy to draw this frame with, planned as a pure frame, or None: plan it in full."""
        self.reused = self.left > 0 and self.base is not None
        if not self.reused:
            return None
        self.left -= 1
        return self.base

    def planned(self, clear: tuple[str, float] | None, allowed: bool) -> None:
        """After a full plan: reuse its choice for the next frames where it was one strategy with at least
        ``slack`` to spare (``clear``: (strategy, slack) or None) and reuse is ``allowed`` now."""
        if allowed and clear is not None and clear[1] >= self.slack:
            self.base, self.left = clear[0], self.frames - 1
        else:
            self.base, self.left = None, 0
