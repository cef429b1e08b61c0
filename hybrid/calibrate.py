"""Calibration of the cost model on this device: time tiles one by one both ways, fit, hold out, save."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .costmodel import CostModel, fit_cost_model
from .features import TileFeatures
from .glcontext import gl_info
from .heightfield import HeightField
from .tiletree import DEFAULT_TAU
from .view import View


@dataclass
class Calibration:
    """The fitted model and the timed tiles it came from."""

    model: CostModel
    features: list[TileFeatures]
    raster_ms: np.ndarray
    raycast_ms: np.ndarray


def time_tiles(ctx, hf: HeightField, views: list[View], tau: float = DEFAULT_TAU, tile_size: int = 256,
               repeats: int = 3, reconstruction: str = "triangles"):
    """Features and measured wall ms (median of repeats, ctx.finish() around each draw) of every selected tile."""
    from .hybrid_frame import HybridRenderer
    r = HybridRenderer(ctx, hf, "hybrid", tile_size=tile_size, reconstruction=reconstruction, oracle_repeats=repeats)
    feats, ras, ray = [], [], []
    try:
        for v in views:
            res = r.render(v, tau, measure=True)
            for row in res.stats["tile_rows"]:
                feats.append(TileFeatures(row["f_pixels"], row["f_triangles"], row["f_slab_cells"], row["level"],
                                          row["f_distance"]))
                ras.append(row["meas_raster_ms"])
                ray.append(row["meas_raycast_ms"])
    finally:
        r.release()
    return feats, np.array(ras), np.array(ray)


def calibrate(ctx, hf: HeightField, views: list[View], tau: float = DEFAULT_TAU, tile_size: int = 256,
              repeats: int = 3, holdout: float = 0.3, seed: int = 0) -> Calibration:
    """Time the tiles of the views and fit the cost model for this context's GL renderer."""
    feats, ras, ray = time_tiles(ctx, hf, views, tau, tile_size, repeats)
    model = fit_cost_model(feats, ras, ray, gl_info(ctx).renderer, holdout, seed)
    return Calibration(model, feats, ras, ray)
