"""Georeferencing with pyproj: ground spacing in metres of a grid in any CRS, and vertical units.

A grid's affine transform (GDAL order: x = a*col + b*row + c, y = d*col + e*row + f, in CRS units) is
turned into a local metric frame at the grid's centre: one pixel step along the columns and one along the
rows, taken symmetrically about the centre, are mapped to longitude/latitude on the CRS's own datum and
measured as geodesics on its ellipsoid (pyproj.Geod). For a geographic CRS that is metres of longitude and
latitude at the centre's latitude; for a projected CRS it is the pixel size divided by the projection's
scale factor there (Web Mercator: the projected size x cos(latitude); UTM on its central meridian: the
projected size / 0.9996), exact on the ellipsoid whether or not the projection is conformal on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.errors import TerrabenchError

# relative change of spacing across the grid above which `info` says how much it varies
VARIES = 1e-3
# east-west and north-south spacing closer than this (relative) are one number: the rest is rounding in the
# geodesics, as on a conformal projection where the scale is the same in every direction
SAME = 1e-9
# band unit spellings GDAL writers use, mapped to pyproj's unit names
UNIT_ALIASES = {
    "m": "metre",
    "meter": "metre",
    "meters": "metre",
    "metres": "metre",
    "ft": "foot",
    "feet": "foot",
    "international foot": "foot",
    "us-ft": "US survey foot",
    "ftus": "US survey foot",
    "us survey foot": "US survey foot",
    "foot_us": "US survey foot",
    "km": "kilometre",
    "cm": "centimetre",
}


@dataclass(frozen=True)
class GroundSpacing:
    """Ground spacing (metres) of one grid step east-west (x) and north-south (y) at the grid's centre."""

    x: float
    y: float
    notes: tuple[str, ...]


def parse_crs(text, what: str):
    """A pyproj CRS from any user input pyproj takes (EPSG:XXXX, WKT, PROJ string); what names its origin."""
    import pyproj

    try:
        return pyproj.CRS.from_user_input(text)
    except pyproj.exceptions.CRSError as exc:
        raise TerrabenchError(f"{what}: {text!r} is not a CRS pyproj knows ({exc})") from None


def describe_crs(crs) -> str:
    """Name, EPSG code (when it has one) and kind of a CRS, e.g. 'WGS 84 / UTM zone 10N (EPSG:32610), projected'."""
    code = crs.to_epsg()
    kind = "geographic" if crs.is_geographic else "projected" if crs.is_projected else crs.type_name
    return f"{crs.name}{f' (EPSG:{code})' if code else ''}, {kind}"


def horizontal_part(crs):
    """The horizontal CRS of a compound CRS, else the CRS itself."""
    if crs.is_compound:
        for sub in crs.sub_crs_list:
            if sub.is_geographic or sub.is_projected or not sub.is_vertical:
                return sub
    return crs


def vertical_metres(crs) -> tuple[float, str] | None:
    """(metres per height unit, unit name) from a compound CRS's vertical part, or None when it has none."""
    for sub in crs.sub_crs_list if crs.is_compound else [crs]:
        if sub.is_vertical:
            axis = sub.axis_info[0]
            return float(axis.unit_conversion_factor), axis.unit_name
    return None


def unit_metres(name: str) -> float | None:
    """Metres per unit for a length unit name (pyproj's unit table, with common abbreviations); None if unknown."""
    import pyproj

    units = pyproj.get_units_map()
    key = UNIT_ALIASES.get(name.strip().lower(), name.strip())
    unit = units.get(key)
    if unit is None or key in ("radian", "degree", "unity", "second") or unit.conv_factor <= 0:
        return None
    return float(unit.conv_factor)


def check_axis_aligned(transform) -> None:
    """Refuse a rotated or sheared affine transform (rows and columns not along the CRS axes)."""
    if transform.b != 0.0 or transform.d != 0.0:
        raise TerrabenchError(
            f"the grid is rotated or sheared in its CRS (transform terms b = {transform.b:g}, d = {transform.d:g}); "
            "terrabench needs rows and columns along the CRS axes: warp it first (e.g. gdalwarp)"
        )
    if transform.a == 0.0 or transform.e == 0.0:
        raise TerrabenchError(f"the transform has a zero pixel size ({transform.a:g} x {transform.e:g})")


def _step_metres(geod, to_lonlat, x0, y0, x1, y1) -> float:
    """Geodesic length in metres between two points given in CRS coordinates."""
    lon, lat = to_lonlat.transform(np.array([x0, x1]), np.array([y0, y1]))
    if not np.all(np.isfinite(lon)) or not np.all(np.isfinite(lat)):
        raise TerrabenchError("the grid lies outside its CRS's valid area (no longitude/latitude there)")
    return float(geod.inv(lon[0], lat[0], lon[1], lat[1])[2])


def check_degrees(crs, transform, rows: int, cols: int) -> None:
    """Refuse a geographic CRS for a grid whose corner coordinates are no longitudes and latitudes in degrees."""
    xs, ys = zip(*(transform @ (c, r) for c in (0, cols) for r in (0, rows)))
    if max(abs(v) for v in ys) <= 90 and max(abs(v) for v in xs) <= 540:
        return
    raise TerrabenchError(
        f"the grid does not fit the CRS {describe_crs(crs)}, whose coordinates are degrees: its corners lie at "
        f"x {min(xs):.6g} .. {max(xs):.6g}, y {min(ys):.6g} .. {max(ys):.6g}, no longitudes and latitudes "
        "(latitude within ±90°), so its unit is another (metres?); give its own CRS with --crs (e.g. a UTM zone, "
        "EPSG:326NN) or its ground spacing with --spacing"
    )


def ground_spacing(crs, transform, rows: int, cols: int) -> GroundSpacing:
    """Ground spacing in metres at the centre of a rows x cols grid with an axis-aligned transform in crs."""
    import pyproj
    from pyproj.crs import GeographicCRS

    horizontal = horizontal_part(crs)
    if not (horizontal.is_geographic or horizontal.is_projected):
        return _local_spacing(crs, horizontal, transform)
    if horizontal.is_geographic:
        check_degrees(crs, transform, rows, cols)
    lonlat = GeographicCRS(datum=horizontal.datum)
    to_lonlat = pyproj.Transformer.from_crs(horizontal, lonlat, always_xy=True)
    geod = horizontal.get_geod()

    def at(row: float) -> tuple[float, float]:
        """East-west and north-south metres of one step about (row, centre column)."""
        col = cols / 2
        xe0, ye0 = transform @ (col - 0.5, row)
        xe1, ye1 = transform @ (col + 0.5, row)
        xn0, yn0 = transform @ (col, row - 0.5)
        xn1, yn1 = transform @ (col, row + 0.5)
        return _step_metres(geod, to_lonlat, xe0, ye0, xe1, ye1), _step_metres(geod, to_lonlat, xn0, yn0, xn1, yn1)

    sx, sy = at(rows / 2)
    if not (np.isfinite(sx) and np.isfinite(sy) and sx > 0 and sy > 0):
        raise TerrabenchError(
            f"the grid's pixels in the CRS {describe_crs(crs)} give no ground spacing (east-west "
            f"{sx!r} m, north-south {sy!r} m); check the CRS (--crs) or pass --spacing"
        )
    if abs(sx - sy) <= SAME * max(sx, sy):
        sx = sy = (sx + sy) / 2
    lon, lat = to_lonlat.transform(*(transform @ (cols / 2, rows / 2)))
    units = horizontal.axis_info[0].unit_name
    where = f"{abs(lat):.4f}° {'N' if lat >= 0 else 'S'}, {abs(lon):.4f}° {'E' if lon >= 0 else 'W'}"
    notes = [
        f"converted: pixels of {abs(transform.a):.6g} x {abs(transform.e):.6g} {units} to "
        f"{sx:.4f} m east-west x {sy:.4f} m north-south, geodesics on the {horizontal.ellipsoid.name} ellipsoid "
        f"at the grid centre ({where})"
    ]
    return GroundSpacing(sx, sy, tuple(notes + _variation_notes(np.array([at(0.5), at(rows - 0.5)]))))


def _local_spacing(crs, horizontal, transform) -> GroundSpacing:
    """The pixel size as ground spacing, for a CRS neither geographic nor projected whose axes have a length unit."""
    axis = horizontal.axis_info[0] if horizontal.axis_info else None
    if axis is None or axis.unit_name in ("degree", "radian") or not axis.unit_conversion_factor:
        raise TerrabenchError(
            f"the CRS {describe_crs(crs)} is neither geographic nor projected, and its axes "
            "are not in a length unit; pass --spacing"
        )
    k = float(axis.unit_conversion_factor)
    return GroundSpacing(
        abs(transform.a) * k,
        abs(transform.e) * k,
        (
            f"pixel size {abs(transform.a):g} x {abs(transform.e):g} {axis.unit_name} "
            f"of a local CRS taken as ground spacing",
        ),
    )


def _variation_notes(edges: np.ndarray) -> list[str]:
    """Notes for each axis whose ground spacing varies by more than VARIES between the grid's first and last rows
    (``edges``: their (east-west, north-south) metres)."""
    notes = []
    for axis, (lo, hi) in (
        ("east-west", (edges[:, 0].min(), edges[:, 0].max())),
        ("north-south", (edges[:, 1].min(), edges[:, 1].max())),
    ):
        if hi - lo > VARIES * (hi + lo) / 2:
            notes.append(
                f"{axis} ground spacing varies across the grid from {lo:.4f} to {hi:.4f} m (between its first "
                "and last rows); the centre's is used"
            )
    return notes
