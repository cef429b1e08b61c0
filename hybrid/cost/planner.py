"""Per-frame plan without a GL context: selected tiles, their features, predicted costs and the choice.

Policies:
    raster, raster_gs, raycast, ...   every tile the same way;
    hybrid      the candidate (raster, raster_gs, raycast) the cost model predicts cheapest for each tile,
                unless drawing every tile one way is predicted faster once the per-frame overheads are counted;
    heuristic   Dick et al.'s fixed rule: ray cast a tile when its triangles outnumber the pixels it covers by
                more than ``threshold`` (default 1), else rasterize (the raster path);
    oracle      each tile timed inside frames every candidate way, the cheapest kept, and the frame compared
                with the pure frames (an evaluation bound: the choice is filled in by the renderer, which
                measures).
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import fields

import numpy as np

from hybrid.camera.view import View
from hybrid.contract import TriangleEstimator
from hybrid.cost.choice import best_assignment_table, subset_masks
from hybrid.cost.features import TileFeatures, feature_columns, tile_features
from hybrid.cost.model import CostModel, all_term_values
from hybrid.errors import TerrabenchError
from hybrid.strategies import (
    STRATEGIES,
    candidates,
    check_policy,
    policy_entry,
    triangle_estimator,
)
from hybrid.tiles.pyramid import TileKey, TilePyramid
from hybrid.tiles.tiletree import DEFAULT_TAU, SelectedTile, select_tiles


class FrameColumns:
    """A frame's per-tile feature columns and predicted ms ((B,) arrays), shared by its TilePlans, which read their
    row as objects only when asked (tables, calibration): drawing needs the choices alone."""

    __slots__ = ("columns", "predicted", "terms")

    def __init__(self, columns: dict, predicted: dict, terms: np.ndarray | None = None):
        self.columns, self.predicted = columns, predicted
        self.terms = all_term_values(columns) if terms is None else terms  # (B, len(ALL_TERMS)), the model's inputs

    def features(self, i: int) -> TileFeatures:
        """Row i's features."""
        return TileFeatures(**{n: self.columns[n][i].item() for n in _FEATURE_NAMES})

    def prediction(self, i: int) -> dict:
        """Row i's predicted ms per candidate."""
        return {n: float(v[i]) for n, v in self.predicted.items()}


_FEATURE_NAMES = tuple(f.name for f in fields(TileFeatures))


class TilePlan:
    """One tile of a frame: where it is, what it costs (predicted, and measured where measured), how it is drawn."""

    __slots__ = ("_features", "_frame", "_predicted", "_row", "choice", "measured", "selected")

    def __init__(
        self,
        selected: SelectedTile,
        features: TileFeatures | None,
        predicted: dict | None,
        choice: str,
        measured: dict | None = None,
        frame: FrameColumns | None = None,
        row: int = -1,
    ):
        self.selected, self.choice, self.measured = selected, choice, {} if measured is None else measured
        self._features, self._predicted, self._frame, self._row = features, predicted, frame, row

    @property
    def features(self) -> TileFeatures | None:
        """The cost model's features of the tile in this view (None for a pure policy)."""
        if self._features is None and self._frame is not None:
            self._features = self._frame.features(self._row)
        return self._features

    @property
    def predicted(self) -> dict:
        """Predicted ms per candidate strategy ({} for a pure policy)."""
        if self._predicted is None:
            self._predicted = self._frame.prediction(self._row) if self._frame is not None else {}
        return self._predicted

    def cost(self, strategy: str) -> float | None:
        """Predicted ms of one strategy for the tile (None where it has no prediction), read from the frame's
        table where the plan shares one, without making the tile's dict of every candidate."""
        if self._predicted is None and self._frame is not None:
            column = self._frame.predicted.get(strategy)
            return None if column is None else float(column[self._row])
        return self.predicted.get(strategy)

    @property
    def key(self) -> TileKey:
        """The tile's address."""
        return self.selected.key

    def __repr__(self) -> str:
        return f"TilePlan({self.selected.key}, choice={self.choice!r})"

    def row(self) -> dict:
        """A flat dict for the tiles table."""
        k = self.selected.key
        features = self.features.as_dict() if self.features is not None else {}
        return {
            "level": k.level,
            "tx": k.tx,
            "ty": k.ty,
            "strategy": self.choice,
            **{f"f_{n}": v for n, v in features.items() if n != "level"},
            **{f"pred_{s}_ms": self.predicted.get(s) for s in candidates()},
            **{f"meas_{s}_ms": self.measured.get(s) for s in candidates()},
        }


def predicted_frame_ms(model: CostModel, plans: list[TilePlan]) -> float | None:
    """The model's predicted ms of a frame of plans as drawn (their choices, each strategy's overhead and a mixed
    frame's); None where some plan has no prediction for its choice."""
    chosen = [p.choice for p in plans]
    used = set(chosen)
    frame = frame_columns(plans)
    if frame is not None and used <= frame.predicted.keys():  # one gather from the frame's table
        names = list(frame.predicted)
        index = {n: i for i, n in enumerate(names)}
        table = np.stack([frame.predicted[n] for n in names])
        costs = table[[index[c] for c in chosen], np.arange(len(plans))]
        return None if np.isnan(costs).any() else model.frame_ms(costs, used)
    known = [c for c in (p.cost(p.choice) for p in plans) if c is not None]
    if not plans or len(known) < len(plans):
        return None
    return model.frame_ms(known, used)


def pure_slack(plans: list[TilePlan], model: CostModel) -> tuple[str, float] | None:
    """(strategy, slack) where every plan of a frame took one strategy and the model priced every tile every way:
    slack is the least, over the other strategies, of what drawing that strategy's cheaper tiles saves at the
    hedged prices (``hedged_picks``) short of its per-frame overhead beyond the chosen one's, as a share of the
    predicted pure frame (ms / ms; negative: another strategy could pay); None for any other frame."""
    frame = frame_columns(plans)
    chosen = {p.choice for p in plans}
    if frame is None or len(chosen) != 1 or not chosen <= frame.predicted.keys():
        return None
    names = tuple(frame.predicted)
    choice = chosen.pop()
    base = names.index(choice)
    table = np.stack([frame.predicted[n] for n in names])
    if len(names) < 2 or not np.isfinite(table).all():
        return None
    overhead, _, tile_err = model.choice_arrays(names)
    factor = 1.0 + tile_err + tile_err[base]
    factor[base] = 1.0
    scaled = table * factor[:, None]
    gain = np.maximum(scaled[base] - scaled, 0.0).sum(axis=1)
    short = np.delete(overhead - overhead[base] - gain, base)
    pure_ms = float(table[base].sum() + overhead[base])
    return choice, float(short.min()) / pure_ms if pure_ms > 0 else 0.0


def frame_columns(plans: list[TilePlan]) -> FrameColumns | None:
    """The feature columns and predictions the plans of one frame share (a mixed policy's batch plan), else None."""
    frame = plans[0]._frame if plans else None
    return frame if frame is not None and all(p._frame is frame for p in plans) else None


def choices(policy: str, columns: dict, predicted: dict, threshold: float = 1.0) -> list[str]:
    """The strategy a policy picks for each of many tiles, from feature columns and predicted ms ((B,) arrays)."""
    check_policy(policy)
    if policy in STRATEGIES:
        return [policy] * len(columns["pixels"])
    rule = policy_entry(policy).rule
    if rule is not None:
        return rule(columns, predicted, threshold)
    names = list(predicted)  # the model's cheapest, unhedged
    costs = np.stack([np.asarray(predicted[n], dtype=np.float64) for n in names])
    return [names[i] for i in np.argmin(costs, axis=0)]


def choose(policy: str, features: TileFeatures, predicted: dict, threshold: float = 1.0) -> str:
    """The strategy a policy picks for one tile (oracle: 'raster' until measured)."""
    columns = {n: np.array([v]) for n, v in vars(features).items()}
    return choices(policy, columns, {s: np.array([v]) for s, v in predicted.items()}, threshold)[0]


def hedged_choices(predicted: dict, model: CostModel) -> list[str]:
    """The hybrid's strategy per tile: the cheapest assignment (``best_assignment``) after hedging against the
    model's error. The frame's base is the strategy whose pure frame is predicted cheapest; a tile leaves it
    only where another strategy is predicted cheaper by more than both models' held-out median relative errors
    per tile together (``model.tile_error``, else the frames' ``model.fit_error``): a choice inside the model's
    error is a coin toss that costs the other strategy's per-frame overhead and, on a CPU rasterizer, risks the
    rare tile that is many times slower than predicted. The pure frames are priced over the tiles every strategy
    can draw (a tile not yet prepared for raster, infinite there, takes ray casting whatever the base); a mixed
    assignment also pays the model's mixed-frame overhead (``model.mix_overhead``). Nor is a
    mix taken whose predicted frame saves less than a share of the base's pure frame: the larger of the model's
    held-out errors of the base's frames and of mixed frames (``model.mix_error``)."""
    names = list(predicted)
    table = np.array([np.asarray(predicted[n], dtype=np.float64) for n in names]).reshape(len(names), -1)
    return [names[i] for i in hedged_picks(table, names, model).tolist()]


def hedged_picks(table: np.ndarray, names: Sequence[str], model: CostModel) -> np.ndarray:
    """``hedged_choices`` as indices into ``names`` (B,), from an (S, B) table of predicted ms in ``names`` order."""
    overhead, err, tile_err = model.choice_arrays(tuple(names))
    known = np.isfinite(table).all(axis=0)  # tiles every strategy can draw
    base = int((np.where(known, table, 0.0).sum(axis=1) + overhead).argmin())
    factor = 1.0 + tile_err + tile_err[base]
    factor[base] = 1.0
    scaled = table * factor[:, None]
    if known.all() and _pure_base_wins(scaled, base, overhead, model.mix_overhead):
        return np.full(table.shape[1], base, dtype=np.int64)
    order = np.array([base] + [i for i in range(len(names)) if i != base])  # ties stay with the base
    pick, _ = best_assignment_table(scaled[order], overhead[order], mixed=model.mix_overhead)
    picks = order[pick]
    pure = np.where(known, base, picks)
    margin = max(err[base], model.mix_error)
    if margin > 0 and np.any(picks != pure):
        cols = np.arange(table.shape[1])
        mixed_ms, pure_ms = (model.frame_ms(table[p, cols], {names[i] for i in p.tolist()}) for p in (picks, pure))
        if pure_ms - mixed_ms < margin * pure_ms:
            return pure
    return picks


def compiled_choice(
    model: CostModel, columns: dict, hedged: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(terms (B, len(ALL_TERMS)), predicted ms (candidates, B), hedged picks (B,) or None) of a frame's feature
    columns in one compiled pass (``hybrid.cost.plan_loops``): ``all_term_values``, ``model.predict_terms`` with
    unknown triangles priced infinite for the raster strategies, and ``hedged_picks``, as their numpy forms
    compute them."""
    from .plan_loops import hedged_pick_loop, predicted_table, term_table

    cols = (np.ascontiguousarray(columns[n], dtype=np.float64) for n in _TERM_FEATURES)
    terms = term_table(*cols)
    table = predicted_table(terms, model.coefficient_table(), model.uses_triangles(), np.inf)
    if not hedged:
        return terms, table, None
    names = model.candidates
    overhead, err, tile_err = model.choice_arrays(names)
    picks = hedged_pick_loop(
        table, overhead, err, tile_err, float(model.mix_overhead), float(model.mix_error), subset_masks(len(names))
    )
    return terms, table, picks


_TERM_FEATURES = ("pixels", "triangles", "visible", "surface_pixels", "slab_cells")


def _pure_base_wins(scaled: np.ndarray, base: int, overhead: np.ndarray, mixed: float) -> bool:
    """Whether ``best_assignment_table`` gives every tile of the (S, B) finite table ``scaled`` to strategy ``base``
    (ordered first), known without pricing the subsets. Let g_s be what strategy s saves over the base on the
    tiles where it is cheaper: a subset's tiles cost at least the base's less the g_s of its other strategies,
    and it pays their overheads (and a mix's, none negative). So where g_s plus the base's overhead is at most
    s's overhead for every other s, no subset costs less than the pure base frame, and ties go to the base's
    subset, the first. A frame whose tiles stay with the base (every frame of the orbit here) takes this path."""
    ov = overhead.tolist()
    if mixed < 0 or min(ov) < 0:
        return False
    gain = np.maximum(scaled[base] - scaled, 0.0).sum(axis=1).tolist()
    return all(g + ov[base] <= o for i, (g, o) in enumerate(zip(gain, ov)) if i != base)


_ESTIMATORS: weakref.WeakKeyDictionary[TilePyramid, TriangleEstimator] = weakref.WeakKeyDictionary()


def default_estimator(pyramid: TilePyramid) -> TriangleEstimator:
    """The raster strategy's triangle estimate for a pyramid, made once per pyramid (it caches per-tile errors)."""
    if pyramid not in _ESTIMATORS:
        _ESTIMATORS[pyramid] = triangle_estimator(pyramid)
    return _ESTIMATORS[pyramid]


def plan_frame(
    pyramid: TilePyramid,
    view: View,
    model: CostModel | None = None,
    triangles_fn: TriangleEstimator | None = None,
    policy: str = "hybrid",
    tau: float = DEFAULT_TAU,
    threshold: float = 1.0,
    batch: bool = True,
    prep_budget_ms: float | None = None,
) -> list[TilePlan]:
    """Selected tiles front to back with the policy's choice of strategy for each.

    A pure policy (one strategy for every tile) needs no features: its plans carry none. A mixed policy gets
    features, the model's predicted ms of every candidate it knows and its choice; ``triangles_fn`` gives the raster
    mesh's triangle counts and their share inside the frustum (default: the raster strategy's CPU estimate from
    the registry, one per pyramid). Features and predictions of all tiles are computed as arrays; ``batch=False`` computes them
    tile by tile instead (the reference path: the same plans, slower). With ``prep_budget_ms`` (streaming), the
    estimate prepares new tiles only within that much wall time; a tile it could not prepare has unknown
    triangles (NaN) and is ray cast this frame (its raster cost is unknown, ray casting needs no such preparation).
    """
    check_policy(policy)
    selected = select_tiles(pyramid, view, tau)
    if policy in STRATEGIES:
        return [TilePlan(s, None, {}, policy) for s in selected]
    if model is None:
        raise TerrabenchError(f"policy {policy!r} needs a cost model (hybrid.cost.model.load_cost_model)")
    if not selected:
        return []
    triangles_fn = triangles_fn or default_estimator(pyramid)
    hedged = policy_entry(policy).rule is None  # the cost model's choice, hedged by its error
    if batch:
        triangles, visible = triangles_fn.many(selected, view, tau, prep_budget_ms)
        columns = feature_columns(pyramid, view, selected, triangles, visible)
        names = model.candidates
        terms, table, picks = compiled_choice(model, columns, hedged)  # unknown triangles: raster infinite
        pred = dict(zip(names, table))
        if picks is not None:
            chosen = [names[i] for i in picks.tolist()]
        else:
            chosen = choices(policy, columns, pred, threshold)
        frame = FrameColumns(columns, pred, terms)
        return [TilePlan(s, None, None, c, frame=frame, row=i) for i, (s, c) in enumerate(zip(selected, chosen))]
    else:
        counts = [triangles_fn.many([s], view, tau) for s in selected]
        features = [tile_features(pyramid, view, s, t[0], v[0]) for s, (t, v) in zip(selected, counts)]
        predicted = [model.predict(f) for f in features]
        if hedged:
            chosen = hedged_choices({n: np.array([q[n] for q in predicted]) for n in predicted[0]}, model)
        else:
            chosen = [choose(policy, f, p, threshold) for f, p in zip(features, predicted)]
    plans = [TilePlan(s, f, p, c) for s, f, p, c in zip(selected, features, predicted, chosen)]
    return plans
