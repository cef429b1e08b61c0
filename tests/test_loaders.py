"""Loaders on the bundled data and on written files of every supported format, and their bad-input errors."""

import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin

from hybrid.errors import TerrabenchError, TerrainLoadError
from hybrid.terrain.datasets import NAMES, get_dataset
from hybrid.terrain.heightfield import HeightField
from hybrid.terrain.loaders import NoDataWarning, load_terrain, save_npz


def test_puget_bundled_values(puget_full):
    hf = puget_full
    assert hf.heights.shape == (1025, 1025)
    assert hf.spacing == 160.0
    assert abs(hf.height_range[1] - 4379.8) < 0.05  # Mount Rainier
    assert hf.extent == (163840.0, 163840.0)
    assert hf.texture.shape == (1024, 1024, 3)
    # south-up rows: Rainier sits about 0.51 of the extent from the NORTH edge, i.e. row ~0.49 from south
    i, j = np.unravel_index(np.argmax(hf.heights), hf.heights.shape)
    assert abs(i / 1024 - 0.49) < 0.02 and abs(j / 1024 - 0.78) < 0.02
    # water texels (blue) coincide with cells at sea level: checks texture orientation
    tex = hf.texture.astype(int)
    blue = (tex[..., 2] > tex[..., 0] + 40) & (tex[..., 2] > tex[..., 1])
    cells0 = (
        (hf.heights[:-1, :-1] == 0)
        & (hf.heights[1:, 1:] == 0)
        & (hf.heights[:-1, 1:] == 0)
        & (hf.heights[1:, :-1] == 0)
    )
    iou = (blue & cells0).sum() / (blue | cells0).sum()
    assert iou > 0.8


def test_png_roundtrip_matches_bundled(tmp_path, puget_full):
    from PIL import Image

    raw = np.rint(puget_full.heights[::-1] / 0.1).astype(np.uint16)
    p = tmp_path / "h.png"
    Image.fromarray(raw).save(p)
    hf = load_terrain(p, vertical_scale=0.1, spacing=160.0)
    assert np.array_equal(hf.heights, puget_full.heights)


def test_geotiff_nodata_and_pixel_size(tmp_path):
    a = np.arange(40 * 30, dtype=np.float32).reshape(40, 30)
    a[5:8, 10:12] = -9999.0
    p = tmp_path / "dem.tif"
    with rasterio.open(
        p,
        "w",
        driver="GTiff",
        width=30,
        height=40,
        count=1,
        dtype="float32",
        nodata=-9999.0,
        crs="EPSG:32610",
        transform=from_origin(500000 - 15 * 25.0, 5e6, 25.0, 25.0),
    ) as dst:
        dst.write(a, 1)
    with pytest.warns(NoDataWarning, match="6 no-data samples"):
        hf = load_terrain(p)
    assert hf.spacing == pytest.approx(25.0 / 0.9996)  # UTM pixels on the central meridian
    assert hf.nodata_filled == 6
    filled = hf.heights[::-1][5:8, 10:12]
    assert np.allclose(filled, np.arange(40 * 30).reshape(40, 30)[5:8, 10:12], atol=1e-2)  # a ramp, continued


def test_npy_npz_hgt_raw(tmp_path):
    a = np.random.default_rng(1).uniform(0, 100, (33, 17)).astype(np.float32)
    np.save(tmp_path / "a.npy", a)
    assert np.array_equal(load_terrain(tmp_path / "a.npy", spacing=2.0).heights, a)
    hf = HeightField(a, 3.0)
    save_npz(hf, tmp_path / "a.npz")
    b = load_terrain(tmp_path / "a.npz")
    assert b.spacing == 3.0 and np.array_equal(b.heights, a)
    srtm = np.full((1201, 1201), 100, dtype=">i2")
    srtm[0, :5] = -32768
    srtm.tofile(tmp_path / "N47W122.hgt")
    with pytest.warns(NoDataWarning):
        h = load_terrain(tmp_path / "N47W122.hgt")
    assert h.nodata_filled == 5 and np.all(h.heights == 100.0)
    assert 62.6 < h.spacing_x < 62.9 and 92.5 < h.spacing_y < 92.8  # 3" at 47.5 N (GDAL reads it from the name)
    save_npz(HeightField(a, (2.0, 3.5)), tmp_path / "pair.npz")
    assert load_terrain(tmp_path / "pair.npz").spacing == (2.0, 3.5)
    a.astype("<f4").tofile(tmp_path / "a.raw")
    r = load_terrain(tmp_path / "a.raw", shape=(33, 17), dtype="<f4", spacing=1.0)
    assert np.array_equal(r.heights, a[::-1])  # raw grids are north-up


def test_nan_is_nodata(tmp_path):
    a = np.ones((10, 10), np.float32)
    a[3, 3] = np.nan
    np.save(tmp_path / "n.npy", a)
    with pytest.warns(NoDataWarning, match="1 no-data"):
        hf = load_terrain(tmp_path / "n.npy", spacing=1.0)
    assert np.all(np.isfinite(hf.heights)) and hf.heights[3, 3] == 1.0


@pytest.mark.parametrize(
    "setup, match",
    [
        (lambda p: p.write_bytes(b""), "empty"),
        (lambda p: np.save(p, np.ones((1, 1))), "at least 2x2"),
        (lambda p: np.save(p, np.full((4, 4), np.nan)), "all 16 samples are no-data"),
        (lambda p: np.save(p, np.array([["a", "b"], ["c", "d"]])), "integers or floats"),
        (lambda p: p.write_bytes(b"\x93NUMPY garbage"), "not a readable NumPy"),
    ],
)
def test_bad_npy_inputs(tmp_path, setup, match):
    p = tmp_path / "bad.npy"
    setup(p)
    with pytest.raises(TerrainLoadError, match=match) as ei:
        load_terrain(p, spacing=1.0)
    assert str(p) in str(ei.value)


def test_bad_files(tmp_path):
    (tmp_path / "x.png").write_bytes(b"not a png at all")
    with pytest.raises(TerrainLoadError, match="not a readable PNG"):
        load_terrain(tmp_path / "x.png", vertical_scale=1, spacing=1)
    with pytest.raises(TerrainLoadError, match="no such file"):
        load_terrain(tmp_path / "missing.tif")
    with pytest.raises(TerrainLoadError, match="unknown suffix"):
        (tmp_path / "a.xyz").write_text("1")
        load_terrain(tmp_path / "a.xyz")
    with pytest.raises(TerrainLoadError, match="spacing"):
        np.save(tmp_path / "s.npy", np.ones((4, 4)))
        load_terrain(tmp_path / "s.npy")
    with pytest.raises(TerrainLoadError, match="SRTM tiles must keep their tile name"):
        (tmp_path / "b.hgt").write_bytes(b"\0" * 100)
        load_terrain(tmp_path / "b.hgt")
    with pytest.raises(TerrabenchError, match="unknown dataset"):
        get_dataset("nowhere")


def test_synthetic_datasets():
    for name in NAMES[1:]:
        a, b = get_dataset(name, size=65, seed=3), get_dataset(name, size=65, seed=3)
        assert np.array_equal(a.heights, b.heights), name  # seeded
        assert a.heights.shape == (65, 65)
    assert np.ptp(get_dataset("flat", 65).heights) == 0
    s = get_dataset("spike", 65).heights
    i, j = np.unravel_index(np.argmax(s), s.shape)
    assert s[i, j] - max(s[i - 1, j], s[i + 1, j], s[i, j - 1], s[i, j + 1]) > 1000
    c = get_dataset("cliff", 65).heights
    assert np.max(np.diff(c, axis=1)) > 500


def test_heightfield_rejects_bad_arrays():
    with pytest.raises(TerrabenchError, match="2-D"):
        HeightField(np.ones(5), 1.0)
    with pytest.raises(TerrabenchError, match="NaN"):
        HeightField(np.array([[0, np.nan], [0, 0]]), 1.0)
    with pytest.raises(TerrabenchError, match="spacing"):
        HeightField(np.ones((3, 3)), 0.0)
    with pytest.raises(TerrabenchError, match="texture"):
        HeightField(np.ones((3, 3)), 1.0, texture=np.zeros((3, 3, 3), np.uint8))
