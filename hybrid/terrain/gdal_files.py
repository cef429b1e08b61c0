"""Height grids in any format GDAL reads (GeoTIFF and COG, SRTM .hgt, Esri .asc, .vrt, ...), through rasterio.

The file gives the CRS, the affine transform, no-data and masks (GDAL's per-band mask: the no-data value, an
internal mask or an alpha band), the band's scale/offset and its vertical unit; hybrid.terrain.georef turns
the CRS and transform into ground spacing in metres. Caller options override the file: ``spacing`` (metres,
one number or (x, y)), ``vertical_scale`` (metres per stored unit), ``crs`` (any CRS pyproj reads).
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from hybrid.errors import TerrabenchError, TerrainLoadError
from hybrid.terrain.assemble import assemble
from hybrid.terrain.georef import (
    check_axis_aligned,
    describe_crs,
    ground_spacing,
    parse_crs,
    unit_metres,
    vertical_metres,
)
from hybrid.terrain.heightfield import HeightField
from hybrid.terrain.window import Crop

if TYPE_CHECKING:
    from rasterio.windows import Window

PASS_SPACING = "pass --spacing METRES (or --spacing X,Y for east-west,north-south metres; `spacing` in a spec entry)"
NO_CRS = (
    "the grid has no CRS, so its ground spacing is unknown; "
    + PASS_SPACING
    + ", or --crs (e.g. --crs EPSG:32610) naming the CRS its transform is in"
)
NO_TRANSFORM = "the grid has no geotransform (no pixel size), so its ground spacing is unknown; " + PASS_SPACING


def _open(path: str):
    """The rasterio dataset of a file, or a TerrainLoadError saying why GDAL cannot read it."""
    import rasterio
    from rasterio.errors import RasterioIOError

    try:
        return rasterio.open(path)
    except RasterioIOError as exc:
        hint = ""
        if path.lower().endswith(".hgt"):
            named = re.fullmatch(r"[NS]\d{2}[EW]\d{3}\.hgt", Path(path).name, re.IGNORECASE)
            hint = (
                " (an SRTM tile holds 1201x1201 or 3601x3601 big-endian int16 samples)"
                if named
                else " (SRTM tiles must keep their tile name, e.g. N47W122.hgt)"
            )
        raise TerrainLoadError(f"{path}: not a readable raster (GDAL: {exc}){hint}") from None


def _vertical(path, crs, band_unit: str, vertical_scale) -> tuple[float, list[str]]:
    """Metres per stored unit: the caller's, else the CRS's vertical unit, else the band's unit, else metres."""
    from_crs = vertical_metres(crs) if crs is not None else None
    if vertical_scale is not None:
        said = f" (the CRS says {from_crs[1]})" if from_crs else f" (the band says {band_unit})" if band_unit else ""
        scale = float(vertical_scale)
        return scale, [f"heights x {scale:g} m per stored unit from --vertical-scale{said}"]
    if from_crs is not None:
        metres, unit = from_crs
        return metres, (
            [] if metres == 1.0 else [f"converted: heights from {unit} (vertical CRS) to metres, x {metres:.10g}"]
        )
    if band_unit:
        band_metres = unit_metres(band_unit)
        if band_metres is None:
            raise TerrainLoadError(
                f"{path}: band unit {band_unit!r} is not a length unit pyproj knows; pass "
                "--vertical-scale (metres per stored unit)"
            )
        return band_metres, (
            []
            if band_metres == 1.0
            else [f"converted: heights from {band_unit} (band unit) to metres, x {band_metres:.10g}"]
        )
    return 1.0, ["heights taken as metres: the file names no vertical unit (pass --vertical-scale to convert)"]


@dataclass
class GridHeader:
    """What a GDAL grid says of itself, before its samples are read: band, shape, orientation, spacing (metres),
    metres per stored unit with the band's scale and offset, and the notes saying where each came from."""

    band: int
    shape: tuple[int, int]
    window: Window | None
    ground: object
    scale: float
    offset: float
    north_up: bool
    east_left: bool
    notes: list
    nodata: float | None


def grid_header(path: str, src, *, vertical_scale=None, spacing=None, crs=None, crop: Crop | None = None) -> GridHeader:
    """The header of an open rasterio dataset (refusals named as load_gdal's)."""
    band = _height_band(path, src)
    shape, window, transform = _window(path, src, crop)
    file_crs = parse_crs(src.crs.to_wkt(), path) if src.crs is not None else None
    georeferenced = not src.transform.is_identity  # GDAL's stand-in when a file has no geotransform
    if src.gcps[0] and not georeferenced and spacing is None:
        raise TerrainLoadError(
            f"{path}: georeferenced by ground control points, not an affine transform; warp "
            "it first (e.g. gdalwarp) or pass --spacing"
        )
    band_scale = float(src.scales[band - 1] or 1.0)
    band_offset = float(src.offsets[band - 1] or 0.0)
    band_unit = (src.units[band - 1] or "").strip()
    notes = [f"read by GDAL's {src.driver} driver"] + (
        [f"window {crop.describe()} of {src.height}x{src.width}"] if crop is not None else []
    )
    try:
        ground, use_crs = _ground(path, file_crs, transform, shape, georeferenced, spacing, crs, notes)
        metres, vnotes = _vertical(path, use_crs, band_unit, vertical_scale)
    except TerrainLoadError:
        raise
    except TerrabenchError as exc:
        raise TerrainLoadError(f"{path}: {exc}") from None
    notes += vnotes
    if band_scale != 1.0 or band_offset != 0.0:
        notes.append(f"band scale {band_scale:g} and offset {band_offset:g} applied")
    return GridHeader(
        band,
        shape,
        window,
        ground,
        band_scale * metres,
        band_offset * metres,
        not georeferenced or transform.e < 0,
        not georeferenced or transform.a > 0,
        notes,
        src.nodatavals[band - 1],
    )


def _height_band(path: str, src) -> int:
    """The (1-based) index of a dataset's one height band; an alpha band beside it is left out."""
    from rasterio.enums import ColorInterp

    heights_bands = [i for i, c in enumerate(src.colorinterp, 1) if c != ColorInterp.alpha]
    if len(heights_bands) != 1:
        raise TerrainLoadError(
            f"{path}: {len(heights_bands)} bands; a height grid has one (plus an optional alpha band)"
        )
    return heights_bands[0]


def _window(path: str, src, crop: Crop | None) -> tuple:
    """(shape, rasterio window or None, affine transform) of the samples read: the whole grid, or its crop."""
    from rasterio.transform import Affine
    from rasterio.windows import Window

    shape = (src.height, src.width)
    window = None
    if crop is not None:
        crop.check(shape, path)
        window = Window(crop.col, crop.row, crop.cols, crop.rows)
        shape = (crop.rows, crop.cols)
    transform = src.transform if crop is None else src.transform @ Affine.translation(crop.col, crop.row)
    return shape, window, transform


def _ground(path: str, file_crs, transform, shape, georeferenced: bool, spacing, crs, notes: list) -> tuple:
    """(ground spacing in metres, CRS used): ``spacing`` if given, else from the CRS (``crs`` over the file's) and
    the transform; what was taken from where is added to ``notes``."""
    use_crs = file_crs
    if crs is not None:
        use_crs = parse_crs(crs, "--crs")
        notes.append(
            f"CRS from --crs: {describe_crs(use_crs)}"
            + (f" (the file says {describe_crs(file_crs)})" if file_crs is not None else "")
        )
    elif file_crs is not None:
        notes.append(f"CRS: {describe_crs(file_crs)}")
    if georeferenced:
        check_axis_aligned(transform)
    if spacing is not None:
        notes.append("ground spacing from --spacing")
        return spacing, use_crs
    if not georeferenced:
        raise TerrainLoadError(f"{path}: {NO_TRANSFORM}")
    if use_crs is None:
        raise TerrainLoadError(f"{path}: {NO_CRS}")
    g = ground_spacing(use_crs, transform, shape[0], shape[1])
    notes += list(g.notes)
    return (g.x, g.y), use_crs


def load_gdal(path, *, vertical_scale=None, spacing=None, crs=None, crop: Crop | None = None, name=None) -> HeightField:
    """Load the height band of a GDAL-readable grid: heights in metres, ground spacing from its CRS (or ``spacing``)."""
    from rasterio.errors import NotGeoreferencedWarning

    path = str(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)  # said below, in terrabench's words
        src = _open(path)
    with src:
        h = grid_header(path, src, vertical_scale=vertical_scale, spacing=spacing, crs=crs, crop=crop)
        try:
            raw = src.read(h.band, window=h.window)
            valid = src.read_masks(h.band, window=h.window)
        except Exception as exc:  # GDAL raises several types for truncated or corrupt data
            raise TerrainLoadError(f"{path}: GDAL cannot read the samples ({type(exc).__name__}: {exc})") from None
    return assemble(
        path,
        raw,
        spacing=h.ground,
        scale=h.scale,
        offset=h.offset,
        missing=valid == 0,
        north_up=h.north_up,
        east_left=h.east_left,
        name=name or Path(path).stem,
        notes=h.notes,
    )
