"""Calibration of the cost model on this device: time tiles inside frames every candidate way, fit, hold out.

It draws through the renderer, so it sits above it (hybrid.cost holds the model, features and fit).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.camera.view import View
from hybrid.contract import CANDIDATES
from hybrid.cost.features import TileFeatures
from hybrid.cost.fit import estimate_overhead, fit_cost_model
from hybrid.cost.model import CostModel
from hybrid.gl.context import gl_info
from hybrid.renderer import Renderer
from hybrid.terrain.heightfield import HeightField
from hybrid.tiles.tiletree import DEFAULT_TAU


@dataclass
class Calibration:
    """The fitted model and the timed tiles it came from."""

    model: CostModel
    features: list[TileFeatures]
    times: dict
    frames: list


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


def calibrate(ctx, hf: HeightField, views: list[View], tau: float = DEFAULT_TAU, tile_size: int = 256,
              repeats: int = 3, holdout: float = 0.3, seed: int = 0) -> Calibration:
    """Time the tiles of the views and fit the cost model for this context's GL renderer."""
    feats, times, frames = time_tiles(ctx, hf, views, tau, tile_size, repeats)
    overhead = {n: estimate_overhead([f[n][0] for f in frames if f[n][1] is not None],
                                     [f[n][1] for f in frames if f[n][1] is not None]) for n in CANDIDATES}
    model = fit_cost_model(feats, times, gl_info(ctx).renderer, holdout, seed, overhead)
    return Calibration(model, feats, times, frames)
