"""Calibration of the cost model on this device: time tiles one by one both ways, fit, hold out, save.

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
    raster_ms: np.ndarray
    raycast_ms: np.ndarray
    frames: list


def time_tiles(ctx, hf: HeightField, views: list[View], tau: float = DEFAULT_TAU, tile_size: int = 256,
               repeats: int = 3, reconstruction: str = "triangles"):
    """Features and measured wall ms of every selected tile drawn alone both ways, and per-frame timings.

    Each time is the median of ``repeats`` draws with ctx.finish() around it. The per-frame records hold the
    tiles' single times and the time of drawing all of them in one call, per strategy (for the overheads).
    """
    feats, ras, ray, frames = [], [], [], []
    with Renderer(ctx, hf, "hybrid", tile_size, oracle_repeats=repeats, reconstruction=reconstruction) as r:
        for v in views:
            res = r.render(v, tau, measure=True)
            rows = res.stats.tile_rows
            frames.append({n: (np.array([row[f"meas_{n}_ms"] for row in rows]), res.stats.together_ms.get(n))
                           for n in CANDIDATES})
            for row in rows:
                feats.append(TileFeatures.from_row(row))
                ras.append(row["meas_raster_ms"])
                ray.append(row["meas_raycast_ms"])
    return feats, np.array(ras), np.array(ray), frames


def calibrate(ctx, hf: HeightField, views: list[View], tau: float = DEFAULT_TAU, tile_size: int = 256,
              repeats: int = 3, holdout: float = 0.3, seed: int = 0) -> Calibration:
    """Time the tiles of the views and fit the cost model for this context's GL renderer."""
    feats, ras, ray, frames = time_tiles(ctx, hf, views, tau, tile_size, repeats)
    overhead = {n: estimate_overhead([f[n][0] for f in frames if f[n][1] is not None],
                                     [f[n][1] for f in frames if f[n][1] is not None]) for n in CANDIDATES}
    model = fit_cost_model(feats, ras, ray, gl_info(ctx).renderer, holdout, seed, overhead)
    return Calibration(model, feats, ras, ray, frames)
