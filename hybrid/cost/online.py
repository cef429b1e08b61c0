"""Online refit of the cost model while the hybrid renders: each strategy's pass in every frame is a measured row.

A frame drawn by the hybrid is one pass per strategy used. Each pass gives one row of that strategy's model,
the same row ``hybrid.cost.fit.fit_frames`` fits: [1 (its per-frame overhead), the sums of its tiles' terms]
against the pass's measured ms. The rows of the last ``AdaptOptions.window`` passes of a strategy are refitted
with non-negative least squares on relative error (scipy's NNLS), pulled toward the starting model by a ridge
(``prior_weight`` rows' worth) so that a few rows move the coefficients only where they say something: the
starting model is first scaled by the median measured / predicted of the window, which corrects a model of
another device or a uniformly wrong one from the first frames, and the ridge pulls toward that scaled model.
Rows more than ``OUTLIER`` times the median relative residual off are dropped and the fit repeated once. A frame
refits one strategy at most, the one with most rows since its last refit: a strategy is refitted every row while
it has fewer than twice ``hold_rows``, every other row while its predictions do not hold, and every
``refit_every`` rows while they do.

Until a strategy has ``level_rows`` rows its level is the machine's: the starting model scaled by the median
measured / starting model's predicted ms of every strategy's recent passes (``machine_scale``), so that a machine
slower than the one the model was fitted on (or one loaded by other work) raises every strategy together, and a
strategy not drawn yet does not look cheap beside one that is.

A strategy the hybrid does not choose gives no rows, so it may be given a few tiles of a frame (exploration):
at most ``explore_tiles`` tiles, those it is predicted to draw cheapest against the frame's choice, paid from a
budget that earns ``explore_share`` of every observed frame's measured ms and is charged what the exploration cost
(``_explore_cost``; a strategy's first pass, which compiles its shaders, is neither charged nor a row).
A strategy with no level of its own yet is priced for exploration at no more than the starting model's level: the
machine's scale, set by the other strategies' rows, may say more about them than about it. A few explored tiles
are a strategy's costly ones and price its tiles, not its frames, so once past its first pass a strategy that drew
fewer than ``level_rows`` passes of more than ``explore_tiles`` tiles may be given a whole frame instead, where it
might beat the frame as chosen at ``OPTIMISM`` times its price and the budget covers the difference.
Until a strategy has ``shape_rows`` passes of more than ``explore_tiles`` tiles, its passes of a few tiles set its
per-frame overhead and its tiles keep the starting model's split (``hybrid.cost.online_fit``). A strategy whose last
``hold_rows`` predictions were within ``hold_error`` (median relative error of passes predicted before they
were fitted) holds, and is explored no more while it holds; nor is it offered a few tiles once its level is
known (``level_known``) though its passes scatter too much to hold one by one.

A mixed frame's own overhead is the median of (frame ms - its passes' ms) over the window's mixed frames less
that of its one-strategy frames.

Whole frames are checked too: a frame the hybrid chose (not explored) is measured against the frame the model
predicted for it. Where the window's mixed frames run over their predictions by more than its one-strategy
frames do, the model's ``mix_error`` (the share a mix must save before the hybrid takes it,
``hybrid.cost.planner.hedged_picks``) becomes that excess: per-pass rows can each fit well while the frames that
mix them do not (a few explored tiles fix a strategy's level but not its tiles, and a frame around several
passes costs more than they do). Checks older than the window age out, so a mix given up is tried again.
"""

from __future__ import annotations

import copy
from collections import deque

import numpy as np

from hybrid.cost.model import _TERM_INDEX, ONLINE_FIT_VERSION, TERMS, CostModel, all_term_values
from hybrid.cost.online_fit import RowWindow, fit_rows, median_of
from hybrid.cost.online_options import AdaptOptions, AdaptStats, Exploration

__all__ = ["AdaptOptions", "AdaptStats", "Exploration", "OnlineModel"]

OPTIMISM = 0.5
"""Exploration prices a strategy at this share of its predicted cost: one that would not pay even then is not
explored (its predictions may be this far off before they hold, and no farther once its level is fitted)."""


class OnlineModel:
    """A cost model refitted from the passes the hybrid draws (see the module docstring); ``model`` is current."""

    def __init__(self, start: CostModel, options: AdaptOptions | None = None, seed: int = 0):
        self.options = options or AdaptOptions()
        self.start = copy.deepcopy(start)
        self.model = copy.deepcopy(start)
        self.model.source = f"{start.source or 'unsaved'}, adapted online"
        self.model.online_fit = ONLINE_FIT_VERSION
        names = self.model.candidates
        self.rows = {s: RowWindow(self.options.window, 1 + len(TERMS[s])) for s in names}
        self._fresh = dict.fromkeys(names, 0)  # rows since the strategy's last refit
        self._seen: set = set()  # strategies whose first pass (compiles, first use) went by
        self._spent: dict = {}  # the last measured cost of exploring each strategy
        self.errors: dict[str, deque[float]] = {s: deque(maxlen=self.options.hold_rows) for s in names}
        w = self.options.window
        self.residual: dict[str, deque[float]] = {"pure": deque(maxlen=w), "mixed": deque(maxlen=w)}
        self.checks: dict[str, deque[tuple[int, float]]] = {"pure": deque(maxlen=w), "mixed": deque(maxlen=w)}
        self.ratios: deque = deque(maxlen=self.options.window)  # measured / starting model's ms of recent passes
        self._own: set = set()  # strategies fitted at their own level (enough rows)
        self._broad = dict.fromkeys(names, 0)  # passes of more than explore_tiles tiles
        self.credit = 0.0
        self.stats = AdaptStats()
        self._rng = np.random.default_rng(seed)

    def holds(self, strategy: str) -> bool:
        """Whether the strategy's recent predictions held (``hold_rows`` passes within ``hold_error``)."""
        e = self.errors[strategy]
        return len(e) == e.maxlen and median_of(e) <= self.options.hold_error

    @property
    def settled(self) -> bool:
        """Whether every candidate's predictions hold."""
        return all(self.holds(s) for s in self.model.candidates)

    def may_explore(self, used: set) -> bool:
        """Whether the budget could pay to explore any candidate outside ``used`` not ``known`` (its per-frame
        overhead at least, at the level exploration prices it, ``_levels``: a strategy not drawn yet is not charged
        the machine's scale): a cheap test before any table is built."""
        m = self.model
        todo = tuple(s for s in m.candidates if s not in used and not self.known(s))
        if not todo:
            return False
        costs = [m.overhead.get(s, 0.0) for s in todo]
        return min(costs) <= self.credit or min(c * v for c, v in zip(costs, self._levels(todo))) <= self.credit

    def level_known(self, strategy: str) -> bool:
        """Whether the strategy's level is known within ``hold_error`` though its passes scatter more than that:
        the standard error of its window's measured / predicted ms (their median absolute deviation, scaled to a
        standard deviation, over the root of their count) is under it, over ``hold_rows`` rows or more. More passes
        of a few explored tiles would not tell it closer than the hedge asks."""
        X, y = self.rows[strategy].arrays()
        pred = X @ self._theta(self.model, strategy)
        ok = pred > 0
        if int(ok.sum()) < self.options.hold_rows:
            return False
        r = y[ok] / pred[ok]
        mid = median_of(r.tolist())
        spread = 1.4826 * median_of(np.abs(r - mid).tolist()) / mid
        return spread / np.sqrt(len(r)) < self.options.hold_error

    def known(self, strategy: str) -> bool:
        """Whether the strategy's predictions hold and it drew ``level_rows`` passes of more than a few tiles
        (its level is then its own frames', not that of the few tiles it was explored on)."""
        return self.holds(strategy) and self._broad[strategy] >= self.options.level_rows

    def explore(self, table: np.ndarray, picks: np.ndarray, names: tuple) -> Exploration | None:
        """Give a candidate the frame does not use a whole frame (``_whole``: one not yet drawn on many tiles),
        else a few tiles (``_offer``: one whose predictions do not hold), when the budget covers its predicted
        cost; of the candidates it covers, the one known least (fewest rows), so that a strategy never drawn is
        not kept waiting by whole frames of one already drawn. ``picks`` (B,) indices into ``names`` are changed
        in place."""
        used = set(picks.tolist())
        if len(picks) == 0:
            return None
        base = table[picks, np.arange(len(picks))]
        chosen = [names[j] for j in used]
        frame = self.model.frame_ms(base, set(chosen))
        levels = self._levels(names)
        offers = []
        for i in (i for i in range(len(names)) if i not in used):
            o = self._whole(table, names, i, frame, levels[i])
            if (
                o is None
                and not self.holds(names[i])
                and np.isfinite(table[i]).any()
                and not self.level_known(names[i])
            ):
                o = self._offer(table, base, names, i, levels[i])
            offers += [] if o is None else [o]
        if not offers:
            return None
        least = min(len(self.rows[names[i]]) for i, _ in offers)  # a candidate it can pay for, known least first
        ties = [o for o in offers if len(self.rows[names[o[0]]]) == least]
        i, tiles = ties[int(self._rng.integers(len(ties)))]
        picks[tiles] = i
        return Exploration(names[i], tiles, float(base[tiles].sum()), len(chosen) == 1)

    def _levels(self, names: tuple) -> list[float]:
        """Per candidate, the share of its predicted ms at which exploration prices it: 1 once it has its own
        level, else at most 1 (the starting model's level where the machine's scale, set by the other strategies'
        rows, would raise it: a strategy never drawn is given the benefit of the doubt, so it gets explored)."""
        if all(s in self._own for s in names):
            return [1.0] * len(names)
        unknown = min(1.0, 1.0 / max(self.machine_scale(), 1e-9))  # once a frame: it reads every row window
        return [1.0 if s in self._own else unknown for s in names]

    def _whole(
        self, table: np.ndarray, names: tuple, i: int, frame: float, level: float
    ) -> tuple[int, np.ndarray] | None:
        """(candidate i, every tile) where candidate i has drawn fewer than ``level_rows`` passes of more than a
        few tiles, could draw the whole frame (every tile's cost known), might beat the frame as chosen
        (``frame`` ms predicted) at ``OPTIMISM`` times its price (its prediction times ``level``), and the budget
        covers the difference: a pass of a few explored tiles prices a strategy's expensive tiles, not its frames."""
        s, o = names[i], self.options
        if s not in self._seen or self._broad[s] >= o.level_rows or len(table[i]) <= o.explore_tiles:
            return None  # a strategy's first pass (uncharged: it compiles) is a few tiles, never a frame
        if not np.isfinite(table[i]).all():
            return None
        whole = level * (self.model.overhead.get(s, 0.0) + float(table[i].sum()))
        if OPTIMISM * whole >= frame or max(whole - frame, self._spent.get(s, 0.0)) > self.credit:
            return None
        return i, np.arange(len(table[i]))

    def _offer(
        self, table: np.ndarray, base: np.ndarray, names: tuple, i: int, level: float
    ) -> tuple[int, np.ndarray] | None:
        """(candidate i, the tiles to give it) where the budget covers exploring it (priced at ``level`` times its
        prediction) and it might pay, else None."""
        ratio = np.where(np.isfinite(table[i]), table[i] / np.maximum(base, 1e-9), np.inf)
        k = min(self.options.explore_tiles, int(np.isfinite(ratio).sum()))
        pool = np.argsort(ratio, kind="stable")[: max(2 * k, 1)]
        tiles = np.sort(self._rng.choice(pool, size=k, replace=False))
        m = self.model
        own_ms = level * (m.overhead.get(names[i], 0.0) + float(table[i, tiles].sum()))
        cost = own_ms + m.mix_overhead - float(base[tiles].sum())
        if max(cost, self._spent.get(names[i], 0.0)) > self.credit or not self._might_pay(table[i], base, names[i]):
            return None
        return i, tiles

    def _might_pay(self, costs: np.ndarray, base: np.ndarray, strategy: str) -> bool:
        """Whether strategy ``strategy``, ``OPTIMISM`` times as costly as predicted (its per-tile ``costs`` (B,) and
        its per-frame overhead), would save this frame more than a mixed frame's overhead on the tiles where it
        beats the frame's choices ``base`` (B,): exploring a strategy that could not win even so buys nothing.
        Until the strategy has ``hold_rows`` rows its level is the starting model's, which may be off by any
        factor: it might pay."""
        if len(self.rows[strategy]) < self.options.hold_rows:
            return True
        finite = np.isfinite(costs)
        gain = float(np.maximum(base[finite] - OPTIMISM * costs[finite], 0.0).sum())
        return gain > OPTIMISM * self.model.overhead.get(strategy, 0.0) + self.model.mix_overhead

    def observe(
        self,
        columns: dict,
        picks: list[str],
        pass_ms: dict,
        frame_ms: float,
        explored: Exploration | None = None,
        predicted_ms: float | None = None,
        terms: np.ndarray | None = None,
    ) -> None:
        """Learn from one drawn frame: feature columns of its tiles ((B,) arrays), each tile's strategy, each
        strategy's measured pass ms, the whole drawing's ms and the model's prediction of it (ms, before this
        frame); refits the strategies drawn. ``terms``: the columns' ``all_term_values`` where the plan has them."""
        if not np.isfinite(frame_ms) or frame_ms <= 0:
            return
        terms = all_term_values(columns) if terms is None else terms
        chosen = np.asarray(picks)
        m = self.model
        learnt = []
        first = set(pass_ms) - self._seen  # drawn for the first time: one-off costs (compiles)
        for s, ms in pass_ms.items():
            if s not in self.rows or not (np.isfinite(ms) and ms > 0):
                continue
            if s not in self._seen:  # a strategy's first pass pays one-off costs: not a row
                self._seen.add(s)
                continue
            x = np.concatenate([[1.0], terms[chosen == s][:, _TERM_INDEX[s]].sum(axis=0)])
            if not np.all(np.isfinite(x)):
                continue
            predicted = float(x @ self._theta(m, s))
            self.errors[s].append(abs(predicted - ms) / ms)
            started = float(x @ self._theta(self.start, s))
            if started > 0:
                self.ratios.append(ms / started)
            self.rows[s].add(x, float(ms))
            self._broad[s] += int(x[1] > self.options.explore_tiles)
            self._fresh[s] += 1
            if self._fresh[s] >= self._cadence(s):
                learnt.append(s)
        kind = "mixed" if len(pass_ms) > 1 else "pure"
        spent = self._explore_cost(explored, pass_ms, frame_ms, first)  # before this frame's gap joins the window
        self.residual[kind].append(frame_ms - sum(pass_ms.values()))
        if explored is None and not first and predicted_ms is not None and predicted_ms > 0:
            self.checks[kind].append((self.stats.frames, frame_ms / predicted_ms))
            m.mix_error = self.mix_margin(self.start.mix_error)
        self.stats.frames += 1
        m.adapted_frames += 1
        self.stats.frame_ms += frame_ms
        self.credit = min(
            self.credit + self.options.explore_share * frame_ms, 20 * self.options.explore_share * frame_ms
        )
        if explored is not None and spent is not None:
            self._spent[explored.strategy] = spent
            self.credit -= spent
            self.stats.explored_frames += 1
            self.stats.explored_tiles += len(explored.tiles)
            self.stats.explore_ms += spent
        if learnt:  # one refit a frame, the strategy with the most rows since its last: a bounded cost
            self._refit([max(learnt, key=lambda s: self._fresh[s])])

    def mix_margin(self, prior: float) -> float:
        """The share a mix must save: how far the window's mixed frames ran over their predictions beyond the
        one-strategy frames (medians of measured / predicted; >= 0), once three mixed frames of the last ``window``
        frames were checked, else ``prior``."""
        since = self.stats.frames - self.options.window
        mixed = [r for k, r in self.checks["mixed"] if k >= since]
        if len(mixed) < 3:
            return prior
        pure = [r for k, r in self.checks["pure"] if k >= since]
        return max(median_of(mixed) / (median_of(pure) if pure else 1.0) - 1.0, 0.0)

    def _explore_cost(self, explored: Exploration | None, pass_ms: dict, frame_ms: float, first: set) -> float | None:
        """What exploring cost a frame (ms): its measured ms beyond the frame as chosen, which is the chosen
        strategies' passes as measured in this frame, the explored tiles at their predicted ms in them, and the
        window's median gap (frame ms less its passes' ms) of frames like the one chosen (one-strategy or mixed);
        or the explored pass beyond the tiles' predicted ms if that is more. Split timing, a depth copy and a
        pass's fixed work are exploration's cost where the frame as chosen has none of them. None: nothing was
        explored; 0: the explored strategy's first pass (one-off costs), in ``first``."""
        if explored is None or explored.strategy not in pass_ms:
            return None
        if explored.strategy in first:
            return 0.0
        gaps = self.residual["pure" if explored.pure else "mixed"]
        chosen = sum(ms for s, ms in pass_ms.items() if s != explored.strategy)
        whole = frame_ms - chosen - explored.base_ms - (max(median_of(gaps), 0.0) if gaps else 0.0)
        return max(whole, pass_ms[explored.strategy] - explored.base_ms, 0.0)

    def _cadence(self, s: str) -> int:
        """Rows between refits of strategy s: every row while it has few, every other while its predictions do not
        hold, ``refit_every`` while they do."""
        if self.holds(s):
            return self.options.refit_every
        return 1 if len(self.rows[s]) < 2 * self.options.hold_rows else 2

    @staticmethod
    def _theta(m: CostModel, s: str) -> np.ndarray:
        """[overhead, coefficients in TERMS order] of strategy s in model m."""
        c = m.coefficients[s]
        return np.array([m.overhead.get(s, 0.0)] + [c.get(t, 0.0) for t in TERMS[s]], dtype=np.float64)

    def machine_scale(self) -> float:
        """How much slower (or faster) this machine draws now than the starting model says, shared by the
        strategies of few rows: the median over strategies with ``level_rows`` rows of their median measured /
        starting model's ms (one vote a strategy, so that one mispredicted strategy drawn often does not set it),
        else the median of every recent pass's."""
        levels = []
        for s, w in self.rows.items():
            if len(w) >= self.options.level_rows:
                X, y = w.arrays()
                pred = X @ self._theta(self.start, s)
                ok = pred > 0
                if ok.any():
                    levels.append(median_of((y[ok] / pred[ok]).tolist()))
        if levels:
            return median_of(levels)
        return median_of(self.ratios) if self.ratios else 1.0

    def _refit(self, names: list[str]) -> None:
        m = copy.copy(self.model)
        o, scale = self.options, self.machine_scale()
        for s in self.model.candidates:
            if s in names:
                self._fresh[s] = 0
            elif s in self._own:
                continue
            X, y = self.rows[s].arrays()  # a strategy of few rows follows the machine's scale only
            own = len(y) >= o.level_rows or self._broad[s] > 0  # or a pass of many tiles told its level
            theta = fit_rows(
                X,
                y,
                self._theta(self.start, s) * (1.0 if own else scale),
                o.prior_weight,
                o.prior_share,
                2 * o.hold_rows,
                o.explore_tiles,
                own_level=own,
            )
            if own:
                self._own.add(s)
            m.overhead = {**m.overhead, s: float(theta[0])}
            m.coefficients = {**m.coefficients, s: dict(zip(TERMS[s], map(float, theta[1:])))}
        mixed, pure = self.residual["mixed"], self.residual["pure"]
        if len(mixed) >= 3:
            m.mix_overhead = max(median_of(mixed) - (median_of(pure) if pure else 0.0), 0.0)
        m.fit_error = {**m.fit_error, **{s: median_of(e) for s in names if len(e := self.errors[s]) == e.maxlen}}
        m.__dict__.pop("_memos", None)
        self.model = m
        self.stats.refits += 1
        self.stats.errors.update({s: median_of(self.errors[s]) for s in names})
