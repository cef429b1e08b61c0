"""Option groups shared by subcommands: the terrain (dataset or file) and the view (camera or flight frame).

Each group is a small dataclass usable from Python, an ``add_*_arguments`` that declares its options and a
``from_args`` that builds the dataclass from parsed arguments (option dests equal the field names).
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, fields

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.window import Crop

from . import argtypes


def from_args(cls, args: argparse.Namespace):
    """An option dataclass filled from the parsed arguments of the same names."""
    return cls(**{f.name: getattr(args, f.name) for f in fields(cls)})


@dataclass(frozen=True)
class TerrainOptions:
    """A terrain: bundled or synthetic dataset name, or a height-field file, with loading overrides."""

    dataset: str = "puget"
    size_samples: int | None = None          # samples a side for synthetic data, or a crop of puget
    seed: int = 0                            # seed for synthetic data
    vertical_scale: float | None = None      # metres per stored unit (files)
    spacing: float | tuple[float, float] | None = None   # metres between samples, or (east-west, north-south)
    crs: str | None = None                   # CRS override for GDAL formats (EPSG:XXXX, WKT, PROJ string)
    crop: Crop | None = None                 # window of a file, rows as stored
    raw_shape: tuple[int, int] | None = None
    raw_dtype: str | None = None
    offset: np.ndarray | None = None         # world x, y, z of the terrain's origin in metres

    def load(self):
        """The HeightField these options name."""
        from hybrid.terrain.sources import TerrainSource
        source = TerrainSource(self.dataset, spacing=self.spacing, vertical_scale=self.vertical_scale, crs=self.crs,
                               crop=self.crop, raw_shape=None if self.raw_shape is None else tuple(self.raw_shape),
                               raw_dtype=self.raw_dtype)
        if source.is_file and self.size_samples is not None:
            raise TerrabenchError("--size-samples applies to synthetic data and puget; for a file, give a window "
                                  "with --crop ROW,COL,ROWS,COLS")
        hf = source.load(size=self.size_samples, seed=self.seed)
        return hf.moved(self.offset) if self.offset is not None else hf


def add_terrain_arguments(p: argparse.ArgumentParser) -> None:
    """Options naming a terrain: bundled/synthetic name or a file, with scale and spacing overrides."""
    p.add_argument("--dataset", default="puget", help="bundled name (puget, fbm, ridged, spike, cliff, staircase, flat, ridges) or a file")
    p.add_argument("--size-samples", type=int, default=None, help="samples per side for synthetic data, or a crop of puget")
    p.add_argument("--seed", type=argtypes.int_in("--seed", 0, 2**32 - 1), default=0, help="seed for synthetic data")
    p.add_argument("--vertical-scale", type=argtypes.positive_float("--vertical-scale", "metres per stored unit"),
                   default=None, help="metres per stored unit (files; overrides the file's vertical unit)")
    p.add_argument("--spacing", type=argtypes.spacing("--spacing"), default=None,
                   help="ground metres between samples, one number or X,Y east-west,north-south (files; overrides "
                        "the CRS)")
    p.add_argument("--crs", default=None, help="CRS of a GDAL-format file, overriding the file's (e.g. EPSG:32610)")
    p.add_argument("--crop", type=argtypes.crop("--crop"), default=None,
                   help="ROW,COL,ROWS,COLS window of a file in samples, rows as stored (row 0 = north edge of "
                        "north-up files)")
    p.add_argument("--raw-shape", type=argtypes.rows_cols("--raw-shape"), default=None, help="ROWSxCOLS for raw files")
    p.add_argument("--raw-dtype", default=None, help="NumPy dtype for raw files, e.g. <u2, <f4")
    p.add_argument("--offset", type=argtypes.vec3("--offset"), default=None, help="place the terrain at world x,y,z metres")


@dataclass(frozen=True)
class ViewOptions:
    """A view: eye and target (metres), the default three-quarter view, or a frame of a flight."""

    eye: np.ndarray | None = None
    target: np.ndarray | None = None
    fov: float = 60.0                        # vertical field of view in degrees
    size: tuple[int, int] = (640, 360)       # viewport width, height in pixels
    near: float | None = None                # metres
    far: float | None = None                 # metres
    flight: str | None = None                # preset name or a .json/.csv flight file
    frames: int = 60                         # frames of a preset flight
    frame: int = 0                           # frame of the flight to render

    def view(self, hf):
        """The View these options name on the terrain hf; refused when its eye is not above the terrain."""
        from hybrid.camera.clearance import check_eye_above
        v = self._view(hf)
        what = (f"--flight {self.flight} frame {self.frame}" if self.flight else
                "--eye" if self.eye is not None else "the default view")
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
            v = View(v.eye, v.target, self.fov, v.width, v.height, self._or(self.near, v.near), self._or(self.far, v.far))
        return v

    @staticmethod
    def _or(value, default):
        return value if value is not None else default


def add_view_arguments(p: argparse.ArgumentParser) -> None:
    """Options choosing the view: eye/target/fov/size or a flight frame."""
    p.add_argument("--eye", type=argtypes.vec3("--eye"), default=None, help="eye x,y,z in world metres")
    p.add_argument("--target", type=argtypes.vec3("--target"), default=None, help="look-at point x,y,z in world metres")
    p.add_argument("--fov", type=float, default=60.0, help="vertical field of view in degrees, (0, 180)")
    p.add_argument("--size", type=argtypes.size("--size"), default="640x360", help="viewport WIDTHxHEIGHT in pixels")
    p.add_argument("--near", type=float, default=None, help="near plane in metres")
    p.add_argument("--far", type=float, default=None, help="far plane in metres")
    p.add_argument("--flight", default=None, help="preset (orbit, flyover, grazing, lookdown, dolly) or a .json/.csv flight")
    p.add_argument("--frames", type=int, default=60, help="frames of a preset flight")
    p.add_argument("--frame", type=int, default=0, help="frame of the flight to render")


def add_reports_argument(p: argparse.ArgumentParser) -> None:
    """The folder that holds reports/<name>/ (run --report and report)."""
    p.add_argument("--reports", default="reports", help="folder for reports")
