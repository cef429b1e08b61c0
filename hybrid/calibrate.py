"""Calibration of the cost model on this device: time whole frames (each candidate alone, and tiles given to the
candidates at random) and fit the model to them (``hybrid.cost.fit.fit_frames``), holding frames out; time tiles
inside frames every candidate way too, for the model's per-tile error.

It draws through the renderer, so it sits above it (hybrid.cost holds the model, features and fit).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.camera.view import View
from hybrid.contract import CANDIDATES
from hybrid.cost.features import TileFeatures
from hybrid.cost.fit import FrameSample, estimate_overhead, fit_frames
from hybrid.cost.model import CostModel, term_values
from hybrid.gl.context import gl_info
from hybrid.renderer import Renderer
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


def time_tiles(ctx, hf: HeightField, views: list[View], tau: float = DEFAULT_TAU, tile_size: int = 256,
               repeats: int = 3, reconstruction: str = "triangles"):
    """Features and measured ms of every selected tile drawn inside frames each candidate way, and per-frame
    records.

    Each time is the median of ``repeats`` frames (``Renderer.time_in_frame``). The per-frame records hold, per
    candidate, the tiles' times and the time of drawing all of them in one call (for the overheads).
    """
    feats, times, frames = [], {n: [] for n in CANDIDATES}, []
    with Renderer(ctx, hf, "hybrid", tile_size, oracle_repeats=repeats, reconstruction=reconstruction) as r:
        for v in views:
            res = r.render(v, tau, measure=True)
            rows = res.stats.tile_rows
            frames.append({n: (np.array([row[f"meas_{n}_ms"] for row in rows]), res.stats.together_ms.get(n))
                           for n in CANDIDATES})
            for row in rows:
                feats.append(TileFeatures.from_row(row))
                for n in CANDIDATES:
                    times[n].append(row[f"meas_{n}_ms"])
    return feats, {n: np.array(t) for n, t in times.items()}, frames


def time_frames(ctx, hf: HeightField, views: list[View], tau: float = DEFAULT_TAU, tile_size: int = 256,
                repeats: int = 3, mixes: int = 6, seed: int = 0) -> list[FrameSample]:
    """Whole frames of every view timed (drawing ms, median of ``repeats``, the assignments of a view interleaved):
    each candidate alone, and ``mixes`` frames whose tiles go at random to two or three candidates (skirts and rays
    stopping behind raster tiles as the renderer draws any mixed frame)."""
    rng = np.random.default_rng(seed)
    out = []
    with Renderer(ctx, hf, "hybrid", tile_size) as r:
        for v in views:
            plans = r.plan(v, tau)
            if not plans:
                continue
            terms = {n: np.array([term_values(p.features, n) for p in plans]) for n in CANDIDATES}
            assigns = [np.array([n] * len(plans)) for n in CANDIDATES]
            for _ in range(mixes):
                pool = rng.choice(CANDIDATES, size=int(rng.integers(2, len(CANDIDATES) + 1)), replace=False)
                assigns.append(rng.choice(pool, size=len(plans)))
            ms = [[] for _ in assigns]
            for rep in range(repeats + 1):                   # the first round warms (uploads, compiles)
                for a, m in zip(assigns, ms):
                    for p, c in zip(plans, a):
                        p.choice = str(c)
                    t = r.render(v, tau, plans=plans).stats.draw_ms
                    if rep:
                        m.append(t)
            for a, m in zip(assigns, ms):
                out.append(FrameSample({n: bool((a == n).any()) for n in CANDIDATES},
                                       {n: terms[n][a == n].sum(axis=0) for n in CANDIDATES}, float(np.median(m))))
    return out


def tile_errors(model: CostModel, feats: list[TileFeatures], times: dict, frames: list) -> dict:
    """Median |predicted - measured| / measured per tile of each candidate, against tiles timed one call each
    inside frames (``time_tiles``), the per-call overhead (``estimate_overhead``) added to the prediction."""
    out = {}
    for n in CANDIDATES:
        call = estimate_overhead([f[n][0] for f in frames if f[n][1] is not None],
                                 [f[n][1] for f in frames if f[n][1] is not None])
        pred = np.array([model.predict(f)[n] for f in feats]) + call
        out[n] = float(np.median(np.abs(pred - times[n]) / times[n]))
    return out


def calibrate(ctx, hf: HeightField, views: list[View], tau: float = DEFAULT_TAU, tile_size: int = 256,
              repeats: int = 3, holdout: float = 0.3, seed: int = 0, mixes: int = 6) -> Calibration:
    """Time frames of the views and fit the cost model for this context's GL renderer; its per-tile error from the
    views' tiles timed one call each."""
    samples = time_frames(ctx, hf, views, tau, tile_size, repeats, mixes, seed)
    feats, times, frames = time_tiles(ctx, hf, views, tau, tile_size, repeats)
    model = fit_frames(samples, gl_info(ctx).renderer, holdout, seed, CANDIDATES)
    model.tiles = len(feats)
    model.tile_error = tile_errors(model, feats, times, frames)
    return Calibration(model, feats, times, frames, samples)
