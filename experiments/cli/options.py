"""Option groups shared by subcommands: the terrain (dataset or file) and the view (camera or flight frame).

Each group is a small dataclass usable from Python (``experiments.scene_options``), an ``add_*_arguments`` that
declares its options and a ``from_args`` that builds the dataclass from parsed arguments (option dests equal the
field names).
"""

from __future__ import annotations

import argparse
from dataclasses import fields

from ..scene_options import TerrainOptions, ViewOptions
from . import argtypes

__all__ = [
    "TerrainOptions",
    "ViewOptions",
    "add_reports_argument",
    "add_terrain_arguments",
    "add_view_arguments",
    "from_args",
]


def from_args(cls, args: argparse.Namespace):
    """An option dataclass filled from the parsed arguments of the same names."""
    return cls(**{f.name: getattr(args, f.name) for f in fields(cls)})


def add_file_arguments(p: argparse.ArgumentParser) -> None:
    """Options for reading a height file: vertical scale, ground spacing, CRS, crop window, raw layout."""
    p.add_argument(
        "--vertical-scale",
        type=argtypes.positive_float("--vertical-scale", "metres per stored unit"),
        default=None,
        help="metres per stored unit (files; overrides the file's vertical unit)",
    )
    p.add_argument(
        "--spacing",
        type=argtypes.spacing("--spacing"),
        default=None,
        help="ground metres between samples, one number or X,Y east-west,north-south (files; overrides the CRS)",
    )
    p.add_argument("--crs", default=None, help="CRS of a GDAL-format file, overriding the file's (e.g. EPSG:32610)")
    p.add_argument(
        "--crop",
        type=argtypes.crop("--crop"),
        default=None,
        help="ROW,COL,ROWS,COLS window of a file in samples, rows as stored (row 0 = north edge of north-up files)",
    )
    p.add_argument("--raw-shape", type=argtypes.rows_cols("--raw-shape"), default=None, help="ROWSxCOLS for raw files")
    p.add_argument("--raw-dtype", default=None, help="NumPy dtype for raw files, e.g. <u2, <f4")


def add_terrain_arguments(p: argparse.ArgumentParser) -> None:
    """Options naming a terrain: bundled/synthetic name or a file, with scale and spacing overrides."""
    p.add_argument(
        "--dataset",
        default="puget",
        help="bundled name (puget, fbm, ridged, spike, cliff, staircase, flat, ridges) or a file",
    )
    p.add_argument(
        "--size-samples", type=int, default=None, help="samples per side for synthetic data, or a crop of puget"
    )
    p.add_argument("--seed", type=argtypes.int_in("--seed", 0, 2**32 - 1), default=0, help="seed for synthetic data")
    add_file_arguments(p)
    p.add_argument(
        "--offset", type=argtypes.vec3("--offset"), default=None, help="place the terrain at world x,y,z metres"
    )


def add_view_arguments(p: argparse.ArgumentParser) -> None:
    """Options choosing the view: eye/target/fov/size or a flight frame."""
    p.add_argument("--eye", type=argtypes.vec3("--eye"), default=None, help="eye x,y,z in world metres")
    p.add_argument("--target", type=argtypes.vec3("--target"), default=None, help="look-at point x,y,z in world metres")
    p.add_argument("--fov", type=float, default=60.0, help="vertical field of view in degrees, (0, 180)")
    p.add_argument("--size", type=argtypes.size("--size"), default="640x360", help="viewport WIDTHxHEIGHT in pixels")
    p.add_argument("--near", type=float, default=None, help="near plane in metres")
    p.add_argument("--far", type=float, default=None, help="far plane in metres")
    p.add_argument(
        "--flight", default=None, help="preset (orbit, flyover, grazing, lookdown, dolly) or a .json/.csv flight"
    )
    p.add_argument("--frames", type=int, default=60, help="frames of a preset flight")
    p.add_argument("--frame", type=int, default=0, help="frame of the flight to render")


def add_reports_argument(p: argparse.ArgumentParser) -> None:
    """The folder that holds reports/<name>/ (run --report and report)."""
    p.add_argument("--reports", default="reports", help="folder for reports")
