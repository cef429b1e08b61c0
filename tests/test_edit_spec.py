"""Edit specs (kind = "edit"): the programme replayed alike for every method, bad values refused by name (exit 2,
no run folder made)."""

import itertools
import json

import pytest

from experiments.cli import main
from experiments.edit_spec import EditSpec, check_programme, frame_brushes, parse_edit_spec
from experiments.spec import load_spec, parse_spec
from hybrid.errors import TerrabenchError
from hybrid.terrain.datasets import puget
from hybrid.terrain.edits import Crater, Flatten

BASE = """
kind = "edit"
name = "e"
dataset = "puget"
dataset_size = 129
frames = 4
sizes = ["64x36"]
tile_size = 32
"""
EDIT = """
[edit]
path = [[0.2, 0.2], [0.8, 0.2], [0.8, 0.8]]
radii = [500.0, 1500.0]
strength = 40.0
edits_per_frame = 2
particles = 64
"""


def test_the_bundled_edit_spec_parses_with_overrides():
    spec = load_spec("edit", {"frames": 2, "sizes": ["96x54"]})
    assert isinstance(spec, EditSpec) and spec.frames == 2 and spec.sizes == ["96x54"]
    assert spec.edit.brush == "crater" and len(spec.edit.radii) >= 2 and spec.edit.particles > 0
    configs = spec.configs()
    assert len(configs) == len(spec.policies) * (len(spec.edit.radii) + 1)
    assert {c.config for c in configs if not c.editing} == {c.config for c in configs if c.edit_radius == 0.0}
    assert len({c.config for c in configs}) == len(configs)


def test_the_programme_is_the_same_brushes_along_the_path():
    spec = parse_spec(BASE + EDIT)
    hf = puget(size=129)
    check_programme(spec, hf)
    frames = frame_brushes(spec, hf, 500.0)
    assert [len(f) for f in frames] == [2, 2, 2, 2]
    flat = [b for f in frames for b in f]
    assert all(isinstance(b, Crater) and b.radius == 500.0 and b.strength == 40.0 for b in flat)
    (w, d), (ox, oy, _) = hf.extent, hf.origin
    assert flat[0].centre == pytest.approx((ox + 0.2 * w, oy + 0.2 * d))
    assert flat[-1].centre == pytest.approx((ox + 0.8 * w, oy + 0.8 * d))
    steps = [abs(a.centre[0] - b.centre[0]) + abs(a.centre[1] - b.centre[1]) for a, b in itertools.pairwise(flat)]
    assert max(steps) == pytest.approx(min(steps), rel=1e-6)  # evenly spaced by length, round the corner
    assert frame_brushes(spec, hf, 500.0) == frames  # replayed identically
    metres = parse_spec(
        BASE
        + EDIT.replace("[[0.2, 0.2], [0.8, 0.2], [0.8, 0.8]]", f"[[{ox + 1000}, {oy + 2000}]]")
        .replace("path", 'units = "metres"\npath')
        .replace("strength = 40.0", "strength = 0.5")
        .replace("[edit]", '[edit]\nbrush = "flatten"\nheight = 100.0')
    )
    b = frame_brushes(metres, hf, 1500.0)[3][1]
    assert isinstance(b, Flatten) and b.centre == (ox + 1000.0, oy + 2000.0) and b.height == 100.0


@pytest.mark.parametrize(
    "change, words",
    [
        (("radii = [500.0, 1500.0]", "radii = [0.0]"), "'radii' must be > 0 m"),
        (("radii = [500.0, 1500.0]", "radii = [-5.0, 10.0]"), "'radii' must be > 0 m"),
        (("strength = 40.0", "strength = nan"), "'strength' must be a finite number"),
        (("[0.8, 0.8]]", "[1.5, 0.8]]"), "way-point 3 (1.5, 0.8) lies off the terrain"),
        (("edits_per_frame = 2", "edits_per_frame = -1"), "'edits_per_frame' must be an integer in [0,"),
        (("particles = 64", "particles = -3"), "'particles' must be an integer in [0,"),
        (("particles = 64", "particles = 1.5"), "'particles' must be an integer"),
        (("strength = 40.0", "strength = 40.0\nspeed = 2"), "unknown keys ['speed']"),
        (("strength = 40.0", 'strength = 40.0\nbrush = "stamp"'), "'brush' must be one of"),
        (("strength = 40.0", "strength = 40.0\nheight = 3.0"), "'height' (world z, m) goes with brush"),
        (('name = "e"', 'name = "e"\npolicies = ["reference"]'), "do not follow edits"),
        (('sizes = ["64x36"]', 'sizes = ["64x36", "32x18"]'), "an edit spec takes one viewport"),
        (("frames = 4", "frames = 0"), "'frames' must be an integer in [1,"),
    ],
)
def test_bad_values_are_refused_by_name(change, words):
    with pytest.raises(TerrabenchError) as exc:
        parse_spec((BASE + EDIT).replace(*change))
    assert words in str(exc.value)


@pytest.mark.parametrize(
    "change, words",
    [
        (
            ("radii = [500.0, 1500.0]", "radii = [500.0, 1e9]"),
            "radius 1e+09 m is larger than terrain 'puget-129' (20480 x 20480 m)",
        ),
        (
            (
                "path = [[0.2, 0.2], [0.8, 0.2], [0.8, 0.8]]",
                'units = "metres"\npath = [[120000.0, 80000.0], [117000.0, 80000.0]]',
            ),
            "way-point 2 (117000, 80000) m lies off terrain 'puget-129'",
        ),
        (("strength = 40.0", "strength = 2e7"), "strength must lie within"),
    ],
)
def test_values_that_do_not_fit_the_terrain_exit_2_before_a_run_folder(tmp_path, capsys, change, words):
    path = tmp_path / "e.toml"
    path.write_text((BASE + EDIT).replace(*change))
    runs = tmp_path / "runs"
    assert main(["run", str(path), "--runs", str(runs), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err
    assert not (runs / "e").exists()


def test_parse_errors_exit_2_from_the_command_line(tmp_path, capsys):
    path = tmp_path / "e.toml"
    path.write_text((BASE + EDIT).replace("strength = 40.0", "strength = nan"))
    assert main(["run", str(path), "--runs", str(tmp_path / "runs")]) == 2
    assert "'strength' must be a finite number" in capsys.readouterr().err
    assert not (tmp_path / "runs" / "e").exists()
    assert main(["run", "edit", "--workers", "local:1", "--runs", str(tmp_path / "runs")]) == 2
    assert "run on one machine" in capsys.readouterr().err


def test_a_tile_store_dataset_is_refused():
    with pytest.raises(TerrabenchError, match="cannot be edited"):
        parse_edit_spec({"dataset": "puget@periodic2049", "edit": {"path": [[0.5, 0.5]]}}, "s")


WAVE = """
[edit.deformation]
kind = "wave"
centre = [0.5, 0.5]
radius = 6000.0
amplitude = 150.0
wavelength = 3000.0
speed = 1500.0
start = 0.0
end = 4.0
seconds_per_frame = 0.5
"""


def test_a_deformation_is_parsed_and_placed_on_the_terrain():
    from experiments.edit_spec import spec_deformation
    from hybrid.terrain.deform import Uplift, Wave

    hf = puget(size=129)
    ox, oy, _ = hf.origin
    spec = parse_spec(BASE + EDIT + WAVE)
    assert spec_deformation(spec, hf) == Wave((ox + 10240.0, oy + 10240.0), 6000.0, 150.0, 3000.0, 1500.0)
    assert [spec.edit.deformation.time(k) for k in range(3)] == [0.5, 1.0, 1.5]
    uplift = WAVE.replace('"wave"', '"uplift"').replace(
        "amplitude = 150.0\nwavelength = 3000.0\nspeed = 1500.0", "rate = -8"
    )
    lifted = parse_spec(BASE + EDIT + uplift)
    assert spec_deformation(lifted, hf) == Uplift((ox + 10240.0, oy + 10240.0), 6000.0, -8.0)
    assert spec_deformation(parse_spec(BASE + EDIT), hf) is None
    assert "deformation" not in parse_spec(BASE + EDIT).to_dict()["edit"]  # run folders of earlier specs resume
    stored = json.loads(json.dumps(spec.to_dict()))  # as a run folder's spec.json holds it
    assert spec.same_as(stored) and not parse_spec(BASE + EDIT).same_as(stored)
    assert stored["edit"]["deformation"]["amplitude"] == 150.0 and stored["edit"]["deformation"]["rate"] is None


@pytest.mark.parametrize(
    "change, words",
    [
        (('kind = "wave"', 'kind = "ripple"'), "[edit.deformation]: 'kind' must be one of wave, uplift, got 'ripple'"),
        (("speed = 1500.0", "speed = 1500.0\nrate = 3.0"), "unknown keys ['rate'] for kind = 'wave'"),
        (("speed = 1500.0\n", ""), "a wave needs ['speed']"),
        (("wavelength = 3000.0", "wavelength = 0.0"), "'wavelength' must be > 0, got 0.0"),
        (("amplitude = 150.0", "amplitude = nan"), "'amplitude' must be a finite number, got nan"),
        (("radius = 6000.0", "radius = -1.0"), "'radius' must be > 0, got -1.0"),
        (("end = 4.0", "end = 0.0"), "0 <= start < end <= 86400 s, got start 0.0 and end 0.0"),
        (("seconds_per_frame = 0.5", "seconds_per_frame = 0"), "'seconds_per_frame' must be > 0, got 0"),
        (("centre = [0.5, 0.5]", "centre = [0.5, 1.5]"), "'centre' (0.5, 1.5) lies off the terrain"),
        (("centre = [0.5, 0.5]", "centre = 3"), "'centre' must be [x, y], got 3"),
    ],
)
def test_bad_deformations_are_refused_by_key_and_value(change, words):
    with pytest.raises(TerrabenchError) as exc:
        parse_spec((BASE + EDIT + WAVE).replace(*change))
    assert words in str(exc.value) and "[edit.deformation]" in str(exc.value)


@pytest.mark.parametrize(
    "change, words",
    [
        (("amplitude = 150.0", "amplitude = 2e7"), "[edit.deformation]: wave deformation displacement 2e+07 m lies"),
        (("radius = 6000.0", "radius = 1e6"), "[edit.deformation]: wave deformation radius must lie in (0, 20480]"),
        (('kind = "wave"', 'kind = "wave"\nunits = 1'), "unknown keys ['units']"),
    ],
)
def test_bad_deformations_exit_2_before_a_run_folder(tmp_path, capsys, change, words):
    path = tmp_path / "e.toml"
    path.write_text((BASE + EDIT + WAVE).replace(*change))
    runs = tmp_path / "runs"
    assert main(["run", str(path), "--runs", str(runs), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err, err
    assert not (runs / "e").exists()
