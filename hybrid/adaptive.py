"""The renderer's side of online adaptation: each strategy's pass timed apart, exploration applied to a frame's
plans, and the drawn frame handed to the online model (``hybrid.cost.online``).

A frame drawn by one strategy needs no extra timing: its pass is the whole drawing. A frame of several
strategies times each pass: on a GPU with a GL timer query per pass (the pass costs the larger of its GPU time
and its CPU issue time, as CPU and GPU work overlap), on a CPU rasterizer with the wall clock and a glFinish
after each pass (timer queries are wrong there).
"""

from __future__ import annotations

import time

import numpy as np

from hybrid.cost.online import Exploration, OnlineModel
from hybrid.cost.planner import TilePlan, frame_columns, predicted_frame_ms
from hybrid.gl.context import gl_finish
from hybrid.gl.timing import timer_queries_valid

SKIRTS = "_skirts"
"""The clock's name for the raster strategies' skirts, drawn after every pass: part of a mixed frame's own cost."""


class PassClock:
    """Per-strategy pass times (ms) of one frame; with ``split`` False it times nothing (the whole drawing is
    the one pass). ``gpu_ms`` is the sum of the passes' timer queries on a GPU, else None."""

    def __init__(self, ctx, split: bool):
        self.ctx, self.split = ctx, split
        self.gpu = split and timer_queries_valid(ctx)
        self.ms: dict[str, float] = {}
        self._queries: list = []

    def run(self, name: str, fn):
        """fn() as the pass of strategy ``name``, timed when splitting."""
        if not self.split:
            return fn()
        t0 = time.perf_counter()
        if self.gpu:
            query = self.ctx.query(time=True)
            with query:
                out = fn()
            self._queries.append((name, query, (time.perf_counter() - t0) * 1e3))
            return out
        out = fn()
        gl_finish(self.ctx)
        self.ms[name] = self.ms.get(name, 0.0) + (time.perf_counter() - t0) * 1e3
        return out

    @property
    def gpu_ms(self) -> float | None:
        """The passes' GPU ms together (timer queries), None where they were not queried."""
        return sum(q.elapsed for _, q, _ in self._queries) / 1e6 if self._queries else None

    def passes(self) -> dict[str, float]:
        """ms of each strategy's pass (skirts apart), once the frame has finished."""
        out = dict(self.ms)
        for name, query, cpu in self._queries:
            out[name] = out.get(name, 0.0) + max(query.elapsed / 1e6, cpu)
        out.pop(SKIRTS, None)
        return out


def explore(online: OnlineModel, plans: list[TilePlan]) -> Exploration | None:
    """Let the online model give a few of the frame's tiles to a strategy it is learning (their plans' choices
    changed); None where it does not."""
    frame = frame_columns(plans)
    if frame is None or not online.may_explore({p.choice for p in plans}):
        return None
    names = tuple(frame.predicted)
    table = np.array([frame.predicted[n] for n in names], dtype=np.float64)
    index = {n: i for i, n in enumerate(names)}
    picks = np.array([index.get(p.choice, -1) for p in plans])
    if (picks < 0).any():
        return None
    found = online.explore(table, picks, names)
    if found is not None:
        for i in found.tiles.tolist():
            plans[i].choice = names[picks[i]]
    return found


def observe(
    online: OnlineModel,
    plans: list[TilePlan],
    pass_ms: dict,
    draw_ms: float,
    explored: Exploration | None,
    predicted: float | None,
) -> None:
    """Hand one drawn frame (its plans, each strategy's pass ms and the drawing's ms) to the online model, with the
    model's prediction of the frame as drawn, made before it (ms; None: not known)."""
    frame = frame_columns(plans)
    if frame is not None:
        online.observe(frame.columns, [p.choice for p in plans], pass_ms, draw_ms, explored, predicted, frame.terms)


def timed_prediction(model, plans: list[TilePlan]) -> tuple[float | None, float]:
    """(``model``'s predicted ms of the frame of ``plans`` as they will be drawn, or None without a model; its
    CPU ms): made before the frame is drawn and learnt from, so that it is an honest prediction."""
    t0 = time.perf_counter()
    predicted = predicted_frame_ms(model, plans) if model is not None else None
    return predicted, (time.perf_counter() - t0) * 1e3


def timed_explore(online: OnlineModel | None, plans: list[TilePlan], learn: bool) -> tuple[Exploration | None, float]:
    """(``explore``'s exploration or None, its CPU ms); nothing done unless ``learn``."""
    t0 = time.perf_counter()
    explored = explore(online, plans) if learn and online is not None else None
    return explored, (time.perf_counter() - t0) * 1e3


def learn(
    online: OnlineModel,
    clock: PassClock,
    plans: list[TilePlan],
    draw_ms: float,
    gpu_ms: float | None,
    issue_ms: float,
    explored: Exploration | None,
    predicted: float | None = None,
) -> float:
    """Hand the drawn frame to the online model (each pass's ms: the clock's, or the whole drawing for a frame of
    one strategy; ``predicted``: ``timed_prediction``'s); its CPU ms back."""
    t0 = time.perf_counter()
    passes = (
        clock.passes()
        if clock.split
        else {plans[0].choice: draw_ms if gpu_ms is None else max(gpu_ms, issue_ms)}
        if plans
        else {}
    )
    observe(online, plans, passes, draw_ms, explored, predicted)
    return (time.perf_counter() - t0) * 1e3
