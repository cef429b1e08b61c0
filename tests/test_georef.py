"""GeoTIFFs written with rasterio in geographic, Web-Mercator, UTM and compound CRSs load with the right ground
spacing (checked against textbook values, ellipsoid formulas and Geod distances made here), orientation,
extent, vertical units and no-data; bad georeferencing is refused by name."""

import math
import warnings

import numpy as np
import pyproj
import pytest
import rasterio
from rasterio.transform import Affine, from_origin

from experiments.cli import main
from hybrid.errors import TerrainLoadError
from hybrid.terrain.loaders import NoDataWarning, load_terrain
from hybrid.terrain.window import Crop

WGS84_A, WGS84_F = 6378137.0, 1 / 298.257223563
ARCSEC3 = 3 / 3600  # degrees


def write_tif(path, north_up, crs, transform, nodata=None, dtype="float32"):
    """A single-band GeoTIFF of a north-up array (first row = north edge)."""
    rows, cols = north_up.shape
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=cols,
        height=rows,
        count=1,
        dtype=dtype,
        crs=crs,
        transform=transform,
        nodata=nodata,
    ) as dst:
        dst.write(north_up.astype(dtype), 1)
    return path


def radii(lat_deg):
    """WGS 84 meridional (M) and prime-vertical (N) radii of curvature in metres (textbook formulas)."""
    e2 = WGS84_F * (2 - WGS84_F)
    s2 = math.sin(math.radians(lat_deg)) ** 2
    return WGS84_A * (1 - e2) / (1 - e2 * s2) ** 1.5, WGS84_A / math.sqrt(1 - e2 * s2)


def bump(rows, cols, at_row, at_col):
    """Heights 100 m with a 500 m peak at (at_row, at_col) in file order."""
    a = np.full((rows, cols), 100.0, np.float32)
    a[at_row, at_col] = 600.0
    return a


@pytest.mark.parametrize("lat", [35.0, 60.0])
def test_geographic_3_arcsecond_spacing_extent_and_north_up(tmp_path, lat):
    rows, cols = 81, 101
    lat_top = lat + (rows / 2) * ARCSEC3  # grid centre on `lat`
    p = write_tif(
        tmp_path / "srtm.tif", bump(rows, cols, 5, 70), "EPSG:4326", from_origin(-120.0, lat_top, ARCSEC3, ARCSEC3)
    )
    hf = load_terrain(p)
    m, n = radii(lat)
    want_x = n * math.cos(math.radians(lat)) * math.radians(ARCSEC3)
    want_y = m * math.radians(ARCSEC3)
    assert hf.spacing_x == pytest.approx(want_x, rel=1e-6) and hf.spacing_y == pytest.approx(want_y, rel=1e-6)
    if lat == 35.0:  # textbook: 3" of latitude ~92.4 m, of longitude ~76 m here
        assert 92.3 < hf.spacing_y < 92.6 and 75.9 < hf.spacing_x < 76.2
    else:
        assert 92.7 < hf.spacing_y < 92.9 and 46.4 < hf.spacing_x < 46.6
    assert hf.extent == pytest.approx(((cols - 1) * want_x, (rows - 1) * want_y), rel=1e-6)
    # the peak 5 rows below the north edge ends up 5 rows below the top of the south-up array
    i, j = np.unravel_index(np.argmax(hf.heights), hf.heights.shape)
    assert (i, j) == (rows - 1 - 5, 70)
    assert any("EPSG:4326" in n for n in hf.notes) and any(n.startswith("converted:") for n in hf.notes)


def test_web_mercator_ground_spacing_is_projected_times_cos_latitude(tmp_path):
    merc = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:3857", always_xy=True)
    x0, y0 = merc.transform(-100.0, 36.0)
    px, rows, cols = 30.0, 64, 64
    transform = from_origin(x0 - px * cols / 2, y0 + px * rows / 2, px, px)
    hf = load_terrain(write_tif(tmp_path / "merc.tif", bump(rows, cols, 10, 10), "EPSG:3857", transform))
    # independent: Geod distances between neighbour pixel centres at the grid centre
    to_ll = pyproj.Transformer.from_crs("EPSG:3857", "EPSG:4326", always_xy=True)
    geod = pyproj.Geod(ellps="WGS84")
    c = (cols / 2, rows / 2)
    (lon_a, lat_a), (lon_b, lat_b) = (
        to_ll.transform(*(transform @ (c[0] - 0.5, c[1]))),
        to_ll.transform(*(transform @ (c[0] + 0.5, c[1]))),
    )
    ew = geod.inv(lon_a, lat_a, lon_b, lat_b)[2]
    (lon_a, lat_a), (lon_b, lat_b) = (
        to_ll.transform(*(transform @ (c[0], c[1] - 0.5))),
        to_ll.transform(*(transform @ (c[0], c[1] + 0.5))),
    )
    ns = geod.inv(lon_a, lat_a, lon_b, lat_b)[2]
    assert hf.spacing_x == pytest.approx(ew, rel=1e-6) and hf.spacing_y == pytest.approx(ns, rel=1e-6)
    # and the textbook rule: ground = projected x cos(latitude), within the ellipsoid's 0.4 %
    assert hf.spacing_x == pytest.approx(px * math.cos(math.radians(36.0)), rel=4e-3)
    assert hf.spacing_y == pytest.approx(px * math.cos(math.radians(36.0)), rel=4e-3)
    assert hf.spacing_x < 0.82 * px  # not the projected 30 m (24 % too wide)


def test_utm_on_and_off_the_central_meridian(tmp_path):
    rows, cols, px = 50, 40, 30.0
    # centred on zone 10's central meridian (easting 500 000 m): scale factor exactly 0.9996
    t = from_origin(500000 - px * cols / 2, 5200000 + px * rows / 2, px, px)
    hf = load_terrain(write_tif(tmp_path / "utm.tif", bump(rows, cols, 3, 30), "EPSG:32610", t))
    assert hf.spacing == pytest.approx(px / 0.9996, rel=1e-7)
    i, j = np.unravel_index(np.argmax(hf.heights), hf.heights.shape)
    assert (i, j) == (rows - 1 - 3, 30)
    # 200 km east of it, beyond the line of true scale: the projection's own point scale factor (UTM is conformal)
    t = from_origin(700000 - px * cols / 2, 5200000 + px * rows / 2, px, px)
    hf = load_terrain(write_tif(tmp_path / "utm_e.tif", bump(rows, cols, 3, 30), "EPSG:32610", t))
    lon, lat = pyproj.Transformer.from_crs("EPSG:32610", "EPSG:4326", always_xy=True).transform(700000, 5200000)
    k = pyproj.Proj("EPSG:32610").get_factors(lon, lat).parallel_scale
    assert k > 1.0 and hf.spacing == pytest.approx(px / k, rel=1e-6)


def test_compound_crs_in_us_feet_converts_heights_and_spacing(tmp_path):
    ftus = 1200 / 3937
    rows, cols = 20, 30
    t = from_origin(6000000, 2100000, 10.0, 10.0)  # NAD83 / California zone 3 (ftUS), 10 ft pixels
    a = np.full((rows, cols), 1000.0, np.float32)  # 1000 US survey feet
    hf = load_terrain(write_tif(tmp_path / "ft.tif", a, "EPSG:2227+6360", t))
    assert np.allclose(hf.heights, 1000 * ftus, rtol=1e-6)
    assert hf.spacing_x == pytest.approx(10 * ftus, rel=2e-4)  # state-plane scale factor is within 1e-4
    assert any("US survey foot" in n for n in hf.notes)
    # --vertical-scale overrides the CRS's unit, and says so
    hf = load_terrain(tmp_path / "ft.tif", vertical_scale=1.0)
    assert np.allclose(hf.heights, 1000.0) and any("--vertical-scale" in n for n in hf.notes)


def test_nodata_voids_filled_and_out_of_range_nodata_ignored(tmp_path):
    rows, cols = 60, 60
    i, j = np.mgrid[0:rows, 0:cols]
    a = (200 + 2 * i + 3 * j).astype(np.int16)
    a[20:26, 30:34] = -32768
    a[40, 10] = -32768
    utm = from_origin(500000, 5e6, 30, 30)
    p = write_tif(tmp_path / "void.tif", a, "EPSG:32610", utm, nodata=-32768, dtype="int16")
    with pytest.warns(
        NoDataWarning,
        match=r"25 no-data samples .* in 2 voids \(largest 24 samples\) filled by "
        r"biharmonic inpainting",
    ):
        hf = load_terrain(p)
    assert hf.nodata_filled == 25
    filled = hf.heights[::-1][20:26, 30:34]
    assert np.allclose(filled, (200 + 2 * i + 3 * j)[20:26, 30:34], atol=1e-3)  # a plane is filled exactly
    # the issue's UTM DEM: int16 with GDAL_NODATA 32767, and a tag out of int16's range: no spurious message
    b = (200 + i).astype(np.int16)
    b[5, 5] = 32767
    p = write_tif(tmp_path / "n32767.tif", b, "EPSG:32610", utm, nodata=32767, dtype="int16")
    with pytest.warns(NoDataWarning, match="1 no-data sample"):
        assert load_terrain(p).heights[::-1][5, 5] == pytest.approx(205.0, abs=0.01)
    p = write_tif(tmp_path / "oor.tif", b, "EPSG:32610", utm, dtype="int16")
    with rasterio.open(p, "r+") as dst:
        dst.nodata = 99999  # no int16 sample can hold it
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        hf = load_terrain(p)
    assert hf.nodata_filled == 0 and np.array_equal(hf.heights[::-1], b.astype(np.float32))


def test_crop_window_crs_override_and_spacing_pair(tmp_path):
    rows, cols = 40, 50
    a = bump(rows, cols, 12, 20)
    p = write_tif(tmp_path / "w.tif", a, "EPSG:32610", from_origin(500000 - 750, 5e6, 30, 30))
    hf = load_terrain(p, crop=Crop(10, 15, 8, 12))  # rows 10..17 as stored (north first), cols 15..26
    assert hf.heights.shape == (8, 12)
    i, j = np.unravel_index(np.argmax(hf.heights), hf.heights.shape)
    assert (i, j) == (8 - 1 - 2, 5)
    with pytest.raises(TerrainLoadError, match="does not fit the 40x50 grid"):
        load_terrain(p, crop=Crop(35, 0, 8, 8))
    # an Esri ASCII grid has no CRS: refused without --spacing, read with a CRS override or a spacing pair
    asc = tmp_path / "g.asc"
    asc.write_text(
        "ncols 3\nnrows 2\nxllcorner 500000\nyllcorner 5000000\ncellsize 10\nNODATA_value -9999\n1 2 3\n4 5 6\n"
    )
    with pytest.raises(TerrainLoadError, match=r"no CRS.*--spacing"):
        load_terrain(asc)
    assert load_terrain(asc, crs="EPSG:32610").spacing == pytest.approx(10 / 0.9996, rel=1e-6)
    hf = load_terrain(asc, spacing=(10.0, 12.5))
    assert (hf.spacing_x, hf.spacing_y) == (10.0, 12.5) and hf.heights[1, 0] == 1.0  # north-up file
    with pytest.raises(TerrainLoadError, match="not a CRS pyproj knows"):
        load_terrain(asc, crs="EPSG:999999")


def test_rotated_and_ungeoreferenced_grids_are_refused(tmp_path):
    a = bump(10, 10, 2, 2)
    p = write_tif(tmp_path / "rot.tif", a, "EPSG:32610", from_origin(500000, 5e6, 30, 30) @ Affine.rotation(10))
    with pytest.raises(TerrainLoadError, match="rotated or sheared"):
        load_terrain(p)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # rasterio's NotGeoreferencedWarning on writing
        q = write_tif(tmp_path / "plain.tif", a, None, Affine.identity())
    with pytest.raises(TerrainLoadError, match=r"no geotransform.*--spacing"):
        load_terrain(q)
    assert load_terrain(q, spacing=5.0).spacing == 5.0


def test_info_prints_crs_spacing_extent_and_conversion(tmp_path, capsys):
    rows, cols = 81, 101
    p = write_tif(
        tmp_path / "g35.tif",
        bump(rows, cols, 5, 5),
        "EPSG:4326",
        from_origin(-120.0, 35.0 + rows / 2 * ARCSEC3, ARCSEC3, ARCSEC3),
    )
    assert main(["info", str(p), "--no-gl"]) == 0
    out = capsys.readouterr().out
    m, n = radii(35.0)
    sx, sy = n * math.cos(math.radians(35.0)) * math.radians(ARCSEC3), m * math.radians(ARCSEC3)
    assert "CRS: WGS 84 (EPSG:4326), geographic" in out
    assert f"spacing:     {sx:g} m east-west x {sy:g} m north-south" in out
    assert f"extent:      {(cols - 1) * sx / 1000:.2f} km x {(rows - 1) * sy / 1000:.2f} km" in out
    assert "converted: pixels of 0.000833333 x 0.000833333 degree" in out


def test_info_refuses_a_grid_without_crs_or_spacing_with_exit_2(tmp_path, capsys):
    p = write_tif(tmp_path / "nocrs.tif", bump(10, 10, 1, 1), None, from_origin(0, 100, 10, 10))
    assert main(["info", str(p), "--no-gl"]) == 2
    err = capsys.readouterr().err
    assert "no CRS" in err and "--spacing" in err and "--crs" in err and "Traceback" not in err
    assert main(["info", str(p), "--no-gl", "--spacing", "10,20"]) == 0
    assert "spacing:     10 m east-west x 20 m north-south" in capsys.readouterr().out
    assert main(["info", str(p), "--no-gl", "--spacing", "10,x"]) == 2
    assert "--spacing (metres) must be a number" in capsys.readouterr().err
    assert main(["info", str(p), "--no-gl", "--spacing", "10", "--size-samples", "5"]) == 2
    assert "--crop" in capsys.readouterr().err  # a file is cut with a window, not a size
