"""`terrabench render --edit FILE.jsonl`: renders after replaying the edits; a bad log exits 2, nothing written."""

import json

import numpy as np
import pytest

from experiments.cli import main
from experiments.scene_options import TerrainOptions
from hybrid.terrain.edit_log import EditLog, LoggedEdit, terrain_id, write_log
from hybrid.terrain.edits import Crater, Raise

ARGS = ["render", "--dataset", "puget", "--size-samples", "129", "--size", "160x90"]


@pytest.fixture(scope="module")
def terrain():
    return TerrainOptions(dataset="puget", size_samples=129).load()


def _log(terrain, path, brushes):
    edits = tuple(LoggedEdit(k, b) for k, b in enumerate(brushes))
    write_log(path, EditLog(terrain_id(terrain), edits))
    return path


@pytest.mark.parametrize("method", ["reference", "raster", "raycast"])
def test_render_replays_the_edits(tmp_path, ctx, terrain, method):
    ox, oy, _ = terrain.origin
    w, d = terrain.extent
    log = _log(
        terrain,
        tmp_path / "e.jsonl",
        [Crater((ox + w / 2, oy + d / 2), w / 4, 2000.0), Raise((ox + w / 3, oy + d / 2), w / 8, -800.0)],
    )
    plain, edited = tmp_path / "plain.png", tmp_path / "edited.png"
    assert main([*ARGS, "--method", method, "--out", str(plain)]) == 0
    assert main([*ARGS, "--method", method, "--out", str(edited), "--edit", str(log)]) == 0
    a, b = np.load(tmp_path / "plain.depth.npy"), np.load(tmp_path / "edited.depth.npy")
    both = np.isfinite(a) & np.isfinite(b)
    assert np.count_nonzero(np.abs(a[both] - b[both]) > 10.0) > 100  # the crater is in the frame
    assert (
        main(
            [
                "render",
                "--dataset",
                "puget",
                "--size-samples",
                "129",
                "--size",
                "160x90",
                "--method",
                "reference",
                "--out",
                str(tmp_path / "ref.png"),
                "--edit",
                str(log),
            ]
        )
        == 0
    )
    ref = np.load(tmp_path / "ref.depth.npy")
    assert (
        np.median(np.abs(b[both & np.isfinite(ref)] - ref[both & np.isfinite(ref)]) / ref[both & np.isfinite(ref)])
        < 2e-3
    )  # drawn against the edited reference


def _bad_logs(terrain, folder):
    ox, oy, _ = terrain.origin
    good = {"frame": 0, "brush": "raise", "centre": [ox + 1000.0, oy + 1000.0], "radius": 500.0, "strength": 5.0}
    ok = _log(terrain, folder / "ok.jsonl", [Raise((ox + 1000.0, oy + 1000.0), 500.0, 5.0)])
    header = ok.read_text().splitlines()[0]
    other = TerrainOptions(dataset="fbm", size_samples=129).load()
    cases = {
        "malformed": (header + '\n{"frame": 0,\n', "line 2: not JSON"),
        "nan": (header + "\n" + json.dumps({**good, "strength": float("nan")}) + "\n", "strength must be finite"),
        "radius": (header + "\n" + json.dumps({**good, "radius": 0.0}) + "\n", "radius must lie in"),
        "huge": (header + "\n" + json.dumps({**good, "radius": 1e9}) + "\n", "radius must lie in"),
        "off": (header + "\n" + json.dumps({**good, "centre": [ox - 5.0, oy]}) + "\n", "lies off terrain"),
        "other": (
            _log(other, folder / "o.jsonl", [Raise((1000.0, 1000.0), 500.0, 5.0)]).read_text(),
            "was made for terrain",
        ),
    }
    return cases


def test_bad_edit_logs_exit_2_and_write_nothing(tmp_path, terrain, capsys):
    logs = tmp_path / "logs"
    logs.mkdir()
    out = tmp_path / "out"
    out.mkdir()
    for name, (text, words) in _bad_logs(terrain, logs).items():
        path = logs / f"{name}.jsonl"
        path.write_text(text)
        assert main([*ARGS, "--method", "raster", "--out", str(out / "a.png"), "--edit", str(path)]) == 2, name
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, (name, err)
        assert not any(out.iterdir()), name
    assert main([*ARGS, "--out", str(out / "a.png"), "--edit", str(logs / "missing.jsonl")]) == 2
    assert "cannot read edit log" in capsys.readouterr().err
