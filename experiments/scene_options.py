"""The terrain and the view a command works on, as frozen dataclasses usable from Python.

The command line fills them (``experiments.cli.options``); calibration and cluster workers take them as they
are, without importing the command line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.window import Crop


@dataclass(frozen=True)
class TerrainOptions:
    """A terrain: bundled or synthetic dataset name, or a height-field file, with loading overrides."""

    dataset: str = "puget"
    size_samples: int | None = None  # samples a side for synthetic data, or a crop of puget
    seed: int = 0  # seed for synthetic data
    vertical_scale: float | None = None  # metres per stored unit (files)
    spacing: float | tuple[float, float] | None = None  # metres between samples, or (east-west, north-south)
    crs: str | None = None  # CRS override for GDAL formats (EPSG:XXXX, WKT, PROJ string)
    crop: Crop | None = None  # window of a file, rows as stored
    raw_shape: tuple[int, int] | None = None
    raw_dtype: str | None = None
    offset: np.ndarray | None = None  # world x, y, z of the terrain's origin in metres

    def load(self):
        """The HeightField these options name."""
        from hybrid.terrain.sources import TerrainSource

        source = TerrainSource(
            self.dataset,
            spacing=self.spacing,
            vertical_scale=self.vertical_scale,
            crs=self.crs,
            crop=self.crop,
            raw_shape=None if self.raw_shape is None else (int(self.raw_shape[0]), int(self.raw_shape[1])),
            raw_dtype=self.raw_dtype,
        )
        if source.is_file and self.size_samples is not None:
            raise TerrabenchError(
                "--size-samples applies to synthetic data and puget; for a file, give a window "
                "with --crop ROW,COL,ROWS,COLS"
            )
        hf = source.load(size=self.size_samples, seed=self.seed)
        return hf.moved(self.offset) if self.offset is not None else hf


@dataclass(frozen=True)
class ViewOptions:
    """A view: eye and target (metres), the default three-quarter view, or a frame of a flight."""

    eye: np.ndarray | None = None
    target: np.ndarray | None = None
    fov: float = 60.0  # vertical field of view in degrees
    size: tuple[int, int] = (640, 360)  # viewport width, height in pixels
    near: float | None = None  # metres
    far: float | None = None  # metres
    flight: str | None = None  # preset name or a .json/.csv flight file
    frames: int = 60  # frames of a preset flight
    frame: int = 0  # frame of the flight to render

    def view(self, hf):
        """The View these options name on the terrain hf; refused when its eye is not above the terrain."""
        from hybrid.camera.clearance import check_eye_above

        v = self._view(hf)
        what = (
            f"--flight {self.flight} frame {self.frame}"
            if self.flight
            else "--eye"
            if self.eye is not None
            else "the default view"
        )
        check_eye_above(hf, v, what)
        return v

    def _view(self, hf):
        from hybrid.camera.flight import get_flight
        from hybrid.camera.view import View, default_view

        w, h = self.size
        if self.flight:
            if self.eye is not None or self.target is not None:
                raise TerrabenchError("give either --flight or --eye/--target, not both")
            v = get_flight(self.flight, hf, frames=self.frames, width=w, height=h).view(self.frame, w, h)
        elif self.eye is not None or self.target is not None:
            if self.eye is None or self.target is None:
                raise TerrabenchError("--eye and --target must be given together")
            d = default_view(hf, 16, 16)
            return View(self.eye, self.target, self.fov, w, h, self._or(self.near, d.near), self._or(self.far, d.far))
        else:
            v = default_view(hf, w, h, self.fov)
        if self.near is not None or self.far is not None or self.fov != v.fov_y:
            v = View(
                v.eye, v.target, self.fov, v.width, v.height, self._or(self.near, v.near), self._or(self.far, v.far)
            )
        return v

    @staticmethod
    def _or(value, default):
        return value if value is not None else default
