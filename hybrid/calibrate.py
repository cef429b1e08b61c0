"""Calibration of the cost model on this device: time whole frames (each candidate alone, and tiles given to the
candidates at random) and tiles inside frames every candidate way, one call each, and fit the model to both
(``hybrid.cost.fit.fit_frames``), holding frames and tiles out for its errors.

It draws through the renderer, so it sits above it (hybrid.cost holds the model, features and fit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.camera.view import View
from hybrid.contract import DEFAULT_FULL_RES
from hybrid.cost.features import TileFeatures
from hybrid.cost.fit import FrameSample, TileSample, fit_frames
from hybrid.cost.model import CostModel, term_values
from hybrid.gl.context import gl_info
from hybrid.renderer import Renderer
from hybrid.strategies import candidates
from hybrid.terrain.heightfield import HeightField
from hybrid.tiles.tiletree import DEFAULT_TAU


@dataclass
class Calibration:
    """The fitted model, the timed frames it came from and the tiles timed for its per-tile error."""

    model: CostModel
    features: list[TileFeatures]
    times: dict
    frames: list
    samples: list


def time_view_tiles(r: Renderer, v: View, tau: float, feats: list, times: dict, frames: list) -> None:
    """A view's tiles drawn inside frames one call each every candidate way, timed (``Renderer.time_in_frame``, the
    median of the renderer's ``oracle_repeats``): their features appended to ``feats``, their ms per candidate to
    ``times`` and, to ``frames``, per candidate the tiles' times and the time of drawing all in one call."""
    res = r.render(v, tau, measure=True)
    rows = res.stats.tile_rows
    frames.append(
        {n: (np.array([row[f"meas_{n}_ms"] for row in rows]), res.stats.together_ms.get(n)) for n in candidates()}
    )
    for row in rows:
        feats.append(TileFeatures.from_row(row))
        for n in candidates():
            times[n].append(row[f"meas_{n}_ms"])


def time_view_frames(r: Renderer, v: View, tau: float, repeats: int, mixes: int, rng) -> list[FrameSample]:
    """A view's whole frames timed (drawing ms, median of ``repeats``, the assignments interleaved): each candidate
    alone, and ``mixes`` frames whose tiles go at random to two or three candidates (skirts and rays stopping behind
    raster tiles as the renderer draws any mixed frame)."""
    plans = r.plan(v, tau)
    if not plans:
        return []
    terms = {n: np.array([term_values(p.features, n) for p in plans]) for n in candidates()}
    assigns = [np.array([n] * len(plans)) for n in candidates()]
    for _ in range(mixes):
        pool = rng.choice(candidates(), size=int(rng.integers(2, len(candidates()) + 1)), replace=False)
        assigns.append(rng.choice(pool, size=len(plans)))
    ms: list[list[float]] = [[] for _ in assigns]
    for rep in range(repeats + 1):  # the first round warms (uploads, compiles)
        for a, m in zip(assigns, ms):
            for p, c in zip(plans, a):
                p.choice = str(c)
            t = r.render(v, tau, plans=plans).stats.draw_ms
            if rep:
                m.append(t)
    return [
        FrameSample(
            {n: bool((a == n).any()) for n in candidates()},
            {n: terms[n][a == n].sum(axis=0) for n in candidates()},
            float(np.median(m)),
        )
        for a, m in zip(assigns, ms)
    ]


def tile_samples(feats: list[TileFeatures], times: dict) -> list[TileSample]:
    """Every tile timed one call each (``time_view_tiles``) as one sample per candidate, with that candidate's
    terms."""
    return [TileSample(n, term_values(f, n), float(times[n][i])) for i, f in enumerate(feats) for n in candidates()]


def calibrate(
    ctx,
    hf: HeightField,
    views: list[View],
    tau: float = DEFAULT_TAU,
    tile_size: int = 256,
    repeats: int = 3,
    holdout: float = 0.3,
    seed: int = 0,
    mixes: int = 6,
    full_res: str = DEFAULT_FULL_RES,
) -> Calibration:
    """Time frames of the views and their tiles one call each, and fit the cost model for this context's GL
    renderer to both, its raster tiles drawn by the full-resolution rule ``full_res`` (recorded in the model). A
    view's frames and tiles are timed one after the other, so that a drift of the machine's speed over the run
    falls on both alike."""
    rng = np.random.default_rng(seed)
    samples: list[FrameSample] = []
    feats: list[TileFeatures] = []
    measured: dict[str, list[float]] = {n: [] for n in candidates()}  # per candidate, each tile's ms
    frames: list[dict] = []
    with Renderer(ctx, hf, "hybrid", tile_size, oracle_repeats=repeats, full_res=full_res) as r:
        for v in views:
            samples += time_view_frames(r, v, tau, repeats, mixes, rng)
            time_view_tiles(r, v, tau, feats, measured, frames)
    times = {n: np.array(t) for n, t in measured.items()}
    model = fit_frames(samples, gl_info(ctx).renderer, holdout, seed, candidates(), tile_samples(feats, times))
    model.tiles = len(feats)
    model.full_res = full_res
    return Calibration(model, feats, times, frames, samples)
