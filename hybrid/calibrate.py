"""Calibration of the cost model on this device: time tiles one by one both ways, fit, hold out, save."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .costmodel import CostModel, estimate_overhead, fit_cost_model
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
    frames: list


def time_tiles(ctx, hf: HeightField, views: list[View], tau: float = DEFAULT_TAU, tile_size: int = 256,
               repeats: int = 3, reconstruction: str = "triangles"):
    """Features and measured wall ms of every selected tile drawn alone both ways, and per-frame timings.

    Each time is the median of ``repeats`` draws with ctx.finish() around it. The per-frame records hold the
    tiles' single times and the time of drawing all of them in one call, per strategy (for the overheads).
    """
    from .hybrid_frame import HybridRenderer
    r = HybridRenderer(ctx, hf, "hybrid", tile_size=tile_size, reconstruction=reconstruction, oracle_repeats=repeats)
    feats, ras, ray, frames = [], [], [], []
    try:
        for v in views:
            res = r.render(v, tau, measure=True)
            rows = res.stats["tile_rows"]
            frames.append({n: (np.array([row[f"meas_{n}_ms"] for row in rows]), res.stats.get(f"together_{n}_ms"))
                           for n in ("raster", "raycast")})
            for row in rows:
                feats.append(TileFeatures(row["f_pixels"], row["f_triangles"], row["f_slab_cells"], row["level"],
                                          row["f_distance"], row["f_visible"], row["f_surface_pixels"]))
                ras.append(row["meas_raster_ms"])
                ray.append(row["meas_raycast_ms"])
    finally:
        r.release()
    return feats, np.array(ras), np.array(ray), frames


def calibrate(ctx, hf: HeightField, views: list[View], tau: float = DEFAULT_TAU, tile_size: int = 256,
              repeats: int = 3, holdout: float = 0.3, seed: int = 0) -> Calibration:
    """Time the tiles of the views and fit the cost model for this context's GL renderer."""
    feats, ras, ray, frames = time_tiles(ctx, hf, views, tau, tile_size, repeats)
    overhead = {n: estimate_overhead([f[n][0] for f in frames if f[n][1] is not None],
                                     [f[n][1] for f in frames if f[n][1] is not None]) for n in ("raster", "raycast")}
    model = fit_cost_model(feats, ras, ray, gl_info(ctx).renderer, holdout, seed, overhead)
    return Calibration(model, feats, ras, ray, frames)
