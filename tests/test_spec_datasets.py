"""Spec dataset entries: tables of a file and its loader options are checked, loaded as given, run, and credited;
the report credits the datasets of its run and no other."""

import numpy as np
import pandas as pd
import pytest
import rasterio
from PIL import Image
from rasterio.transform import from_origin

from experiments.report import write_report
from experiments.runner import run_spec
from experiments.spec import load_spec, parse_spec
from experiments.spec_datasets import credit_lines
from hybrid.errors import TerrabenchError
from hybrid.terrain.datasets import PUGET_CREDIT


def utm_tif(path, rows=40, cols=50):
    """A UTM GeoTIFF with a peak at stored row 12, column 20 (north-up), on zone 10's central meridian."""
    a = np.full((rows, cols), 100.0, np.float32)
    a[12, 20] = 700.0
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=cols,
        height=rows,
        count=1,
        dtype="float32",
        crs="EPSG:32610",
        transform=from_origin(500000 - 15 * cols, 5e6, 30, 30),
    ) as dst:
        dst.write(a, 1)
    return path


def test_table_entry_loads_with_its_options(tmp_path):
    tif = utm_tif(tmp_path / "dem.tif")
    crop = "{row = 10, col = 15, rows = 8, cols = 12}"
    spec = parse_spec(f'''
name = "files"
datasets = ["fbm", {{path = "{tif}", name = "dem", spacing = [20.0, 25.0], crop = {crop}}}]
''')
    assert {c.dataset for c in spec.configs()} == {"fbm", "dem"}
    assert any(c.config.startswith("dem-s0-") for c in spec.configs())
    hf = spec.source("dem").load()
    assert hf.heights.shape == (8, 12) and (hf.spacing_x, hf.spacing_y) == (20.0, 25.0)
    assert hf.height_range == (100.0, 700.0)
    i, j = np.unravel_index(np.argmax(hf.heights), hf.heights.shape)
    assert (i, j) == (8 - 1 - 2, 5)  # stored row 12 = window row 2, north-up
    # the array-of-tables form; without a spacing, the file's CRS gives it
    spec = parse_spec(
        f'''
frames = 2
[[datasets]]
path = "{tif}"
vertical_scale = 0.5
crs = "EPSG:32610"
credit = "made in a test"
''',
        "s.toml",
    )
    hf = spec.source(str(tif)).load()
    assert hf.spacing == pytest.approx(30 / 0.9996) and hf.height_range == (50.0, 350.0)
    assert spec.source(str(tif)).credit_line() == f"{tif}: made in a test"


def test_relative_paths_are_taken_from_the_spec_folder(tmp_path, monkeypatch):
    (tmp_path / "data").mkdir()
    utm_tif(tmp_path / "data" / "dem.tif")
    (tmp_path / "s.toml").write_text('datasets = [{path = "data/dem.tif", name = "d"}, "data/dem.tif"]\n')
    monkeypatch.chdir("/")
    spec = load_spec(tmp_path / "s.toml")
    assert spec.source("d").load().heights.shape == (40, 50)
    assert spec.source(str(tmp_path / "data" / "dem.tif")).load().heights.shape == (40, 50)


@pytest.mark.parametrize(
    "entry, match",
    [
        ('{name = "x"}', "needs 'path'"),
        ('{path = "a.tif", spacing = -1}', "'spacing' .* > 0"),
        ('{path = "a.tif", spacing = [1, 2, 3]}', "east-west, north-south"),
        ('{path = "a.tif", vertical_scale = "big"}', "vertical_scale"),
        ('{path = "a.tif", crop = {row = 0, col = 0, rows = 1, cols = 5}}', "at least 2x2"),
        ('{path = "a.tif", crop = [0, 0, 4, 4]}', "row, col, rows, cols"),
        ('{path = "a.tif", crs = "EPSG:999999"}', "not a CRS pyproj knows"),
        ('{path = "a.tif", colour = "red"}', "unknown"),
        ('{path = "puget", spacing = 10}', "apply to files"),
        ('"fbm", {path = "fbm", name = "fbm"}', "appear twice"),
        ("3", "names, paths or tables"),
    ],
)
def test_bad_dataset_entries_are_refused_by_name(entry, match):
    with pytest.raises(TerrabenchError, match=match):
        parse_spec(f"datasets = [{entry}]\n", "bad.toml")


def test_credit_lines_only_for_datasets_used():
    datasets = ["puget", "fbm", {"path": "/d/dem.tif", "name": "dem", "credit": "USGS 3DEP"}, "/d/other.tif"]
    assert credit_lines(datasets, ["fbm"]) == []
    assert credit_lines(datasets, ["puget", "fbm"]) == [PUGET_CREDIT]
    assert credit_lines(datasets, ["dem"]) == ["dem: USGS 3DEP"]
    assert "no credit given" in credit_lines(datasets, ["/d/other.tif"])[0]


def test_a_16_bit_png_dataset_runs_and_is_credited(tmp_path, ctx):
    i, j = np.mgrid[0:65, 0:65]
    heights = (2000 + 800 * np.sin(i / 9.0) * np.cos(j / 11.0)).astype(np.uint16)  # decimetres, north-up
    Image.fromarray(heights).save(tmp_path / "hill.png")
    spec = parse_spec(
        """
name = "png"
datasets = [{path = "hill.png", name = "hill", spacing = 30.0, vertical_scale = 0.1, credit = "drawn by a test"}]
flights = ["orbit"]
frames = 1
policies = ["raycast"]
sizes = ["48x32"]
repeats = 3
tile_size = 32
supersample = 1
flip = false
""",
        "png.toml",
        tmp_path,
    )
    folder = run_spec(spec, tmp_path / "runs", ctx, progress=False)
    assert not (folder / "errors.jsonl").exists()
    assert set(pd.read_parquet(folder / "frames.parquet")["dataset"]) == {"hill"}
    text = write_report(folder, tmp_path / "reports").read_text()
    assert "hill: drawn by a test" in text and "Puget Sound" not in text
