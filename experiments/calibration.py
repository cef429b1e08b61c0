"""Calibration of the cost model on the views of named flights over a terrain, wherever a GL context is: this
process (``terrabench calibrate``) or a cluster worker (``experiments.cluster``)."""

from __future__ import annotations

from .scene_options import TerrainOptions


def calibrate_here(
    ctx,
    terrain: TerrainOptions,
    flights,
    frames: int,
    size: tuple[int, int],
    tau: float,
    tile_size: int,
    repeats: int,
    holdout: float,
):
    """The Calibration of this GL context on views of the flights (size in pixels, tau in pixels)."""
    from hybrid.calibrate import calibrate
    from hybrid.camera.flight import get_flight

    hf = terrain.load()
    w, h = size
    views = [v for name in flights for v in get_flight(name, hf, frames=frames, width=w, height=h).views()]
    return calibrate(ctx, hf, views, tau, tile_size, repeats, holdout)
