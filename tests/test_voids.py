"""Void filling: smooth across an irregular void on a curved slope (no grooves), within each void's rim range,
and the warning names the count, the largest void, the method and what the rim bound moved."""

import numpy as np
import pytest
from scipy import ndimage

from hybrid.camera.flight import preset
from hybrid.camera.view import default_view
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.terrain.datasets import puget
from hybrid.terrain.loaders import NoDataWarning, load_terrain
from hybrid.terrain.voids import fill_voids
from hybrid.tiles.pyramid import TilePyramid


def curved_slope(n=120):
    """A smooth sloped and curved surface in metres (30 m cells): a tilted plane with broad undulations."""
    i, j = np.mgrid[0:n, 0:n].astype(np.float64)
    return 3.0 * i + 2.0 * j + 60.0 * np.sin(j / 14.0) * np.cos(i / 19.0)


def blob(n=120, seed=4):
    """One irregular void of a few hundred samples (a thresholded smooth random field, largest piece)."""
    field = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal((n, n)), 5)
    field[:15], field[-15:], field[:, :15], field[:, -15:] = -1, -1, -1, -1
    lab, _ = ndimage.label(field > np.quantile(field, 0.97), np.ones((3, 3)))
    biggest = np.argmax(np.bincount(lab.ravel())[1:]) + 1
    return lab == biggest


def second_differences(h):
    """|h[k-1] - 2 h[k] + h[k+1]| along rows and columns, at interior samples (NaN at the border)."""
    d = np.full(h.shape, np.nan)
    core = np.abs(h[:-2, 1:-1] - 2 * h[1:-1, 1:-1] + h[2:, 1:-1])
    core = np.maximum(core, np.abs(h[1:-1, :-2] - 2 * h[1:-1, 1:-1] + h[1:-1, 2:]))
    d[1:-1, 1:-1] = core
    return d


def test_fill_is_smooth_and_within_the_rim_range_on_an_irregular_void():
    h = curved_slope()
    void = blob()
    assert 150 < void.sum() < 800 and ndimage.label(void, np.ones((3, 3)))[1] == 1
    filled, report = fill_voids(np.where(void, -32768.0, h), void)
    assert (report.samples, report.voids, report.largest) == (int(void.sum()), 1, int(void.sum()))
    rim = ndimage.binary_dilation(void, np.ones((3, 3))) & ~void
    assert h[rim].min() <= filled[void].min() and filled[void].max() <= h[rim].max()
    # no grooves: the largest second difference at and next to the void is of the surroundings' size
    d = second_differences(filled)
    near = ndimage.binary_dilation(void, np.ones((3, 3)), iterations=2)
    around = ndimage.binary_dilation(void, np.ones((3, 3)), iterations=8) & ~near
    assert np.nanmax(d[near]) <= 1.5 * np.nanmax(d[around])
    # and it follows the surface it replaces (relief inside the void is over 50 m)
    assert np.ptp(h[void]) > 50 and np.abs(filled - h)[void].max() < 0.01 * np.ptp(h[void])


def test_overshoot_is_bounded_by_the_rim_and_reported(tmp_path):
    i, j = np.mgrid[0:61, 0:61].astype(np.float64)
    dome = 1000.0 - 0.5 * ((i - 30) ** 2 + (j - 30) ** 2)  # the summit lies inside the void
    void = (i - 30) ** 2 + (j - 30) ** 2 <= 36
    second = np.zeros_like(void)
    second[5:7, 50:53] = True
    heights = np.where(void | second, np.nan, dome).astype(np.float32)
    np.save(tmp_path / "dome.npy", heights)
    with pytest.warns(NoDataWarning) as rec:
        hf = load_terrain(tmp_path / "dome.npy", spacing=10.0)
    msg = str(rec[0].message)
    n = int(void.sum())
    assert f"{n + 6} no-data samples" in msg and "in 2 voids" in msg and f"largest {n} samples" in msg
    assert "biharmonic inpainting" in msg and "bounded by its rim's height range" in msg
    held = int(msg.split("(")[-1].split(" samples held")[0])
    assert held > 0  # the continued dome rose above its rim
    rim = ndimage.binary_dilation(void, np.ones((3, 3))) & ~void
    assert hf.heights[void].max() == pytest.approx(dome[rim].max(), abs=1e-3)
    assert hf.heights[void].min() >= dome[rim].min() - 1e-3
    assert any(note.startswith("no-data:") and "samples held" in note for note in hf.notes)


def srtm_like(tmp_path):
    """An int16 GeoTIFF of whole-metre heights (Puget's window, north-up) with no-data holes of a few hundred
    samples, as an SRTM tile with voids: its path and the holes (north-up)."""
    import rasterio
    from rasterio.transform import from_origin

    base = puget(size=257, with_texture=False)
    ints = np.rint(base.heights[::-1]).astype(np.int16)
    holes = blob(257, seed=7) | np.roll(blob(257, seed=11), 60, axis=1)
    path = tmp_path / "srtm_voids.tif"
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=257,
        height=257,
        count=1,
        dtype="int16",
        crs="EPSG:32610",
        transform=from_origin(500000.0, 5200000.0, 30.0, 30.0),
        nodata=-32768,
    ) as dst:
        dst.write(np.where(holes, -32768, ints).astype(np.int16), 1)
    return path, holes


def test_an_integer_source_with_voids_stays_on_its_step(tmp_path):
    path, holes = srtm_like(tmp_path)
    assert holes.sum() > 300
    with pytest.warns(NoDataWarning, match="integer step"):
        hf = load_terrain(path)
    assert hf.nodata_filled == int(holes.sum()) and hf.source_step == (1.0, 0.0)
    assert np.array_equal(hf.heights, np.rint(hf.heights))  # the fill is whole metres too
    pyr = TilePyramid(hf, 64)
    for level in range(pyr.max_level + 1):  # so every tile's 16-bit codes are exact
        rows, cols = pyr.tile_counts(level)
        ty, tx = np.divmod(np.arange(rows * cols), cols)
        assert not pyr.quantization_errors_at(level, tx, ty).any()


@pytest.mark.gl
def test_a_void_filled_integer_source_ray_casts_within_float_precision_of_the_reference(ctx, tmp_path):
    path, _ = srtm_like(tmp_path)
    with pytest.warns(NoDataWarning):
        hf = load_terrain(path)
    views = [default_view(hf, 200, 120)] + preset("flyover", hf, 3, 200, 120).views()
    with Renderer(ctx, hf, "raycast", 64) as rc, ReferenceRenderer(ctx, hf) as ref:
        for view in views:
            a, b = rc.render(view, 2 / 3, mode="shaded"), ref.render(view, mode="shaded")
            both = a.mask & b.mask
            assert both.mean() > 0.1
            rel = np.abs(a.distance[both] - b.distance[both]) / b.distance[both]
            assert np.median(rel) <= 1e-6, np.median(rel)
