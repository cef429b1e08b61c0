"""The command line: render writes image + depth; user errors end in one message and exit code 2."""

import numpy as np
import pytest
from PIL import Image

from experiments.cli import main


def test_render_reference_writes_png_and_depth(tmp_path, ctx):
    out = tmp_path / "ref.png"
    rc = main(["render", "--dataset", "puget", "--size-samples", "129", "--size", "160x90", "--out", str(out)])
    assert rc == 0
    img = np.array(Image.open(out))
    depth = np.load(tmp_path / "ref.depth.npy")
    assert img.shape == (90, 160, 3) and depth.shape == (90, 160) and depth.dtype == np.float32
    assert np.isfinite(depth).mean() > 0.2 and np.all(depth[np.isfinite(depth)] > 0)


def test_render_flight_frame(tmp_path, ctx):
    out = tmp_path / "g.png"
    assert (
        main(
            [
                "render",
                "--dataset",
                "ridges",
                "--size-samples",
                "65",
                "--flight",
                "grazing",
                "--frame",
                "2",
                "--size",
                "96x64",
                "--out",
                str(out),
                "--shading",
                "height",
            ]
        )
        == 0
    )
    assert out.exists()


@pytest.mark.parametrize(
    "argv, match",
    [
        (["render", "--out", "X/a.png"], "folder"),
        (["render", "--out", "OUT/a.jpg"], "must end in .png"),
        (["render", "--out", "OUT/a.png", "--fov", "0"], "fov_y"),
        (["render", "--out", "OUT/a.png", "--size", "0x10"], "width"),
        (["render", "--out", "OUT/a.png", "--size", "big"], "WIDTHxHEIGHT"),
        (["render", "--out", "OUT/a.png", "--near", "10", "--far", "1"], "far"),
        (["render", "--out", "OUT/a.png", "--tau", "-1"], "tau"),
        (["render", "--out", "OUT/a.png", "--dataset", "mars"], "unknown dataset"),
        (["render", "--out", "OUT/a.png", "--dataset", "missing.tif"], "no such file"),
        (["render", "--out", "OUT/a.png", "--flight", "loop"], "unknown flight"),
        (["render", "--out", "OUT/a.png", "--eye", "1,2", "--target", "0,0,0"], "three numbers"),
        (["info", "nothing.hgt", "--no-gl"], "no such file"),
    ],
)
def test_user_errors_exit_2(tmp_path, capsys, argv, match):
    argv = [a.replace("OUT", str(tmp_path)) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err
    assert not any(tmp_path.iterdir())  # nothing partially written


def test_unknown_method_is_argparse_error(capsys, tmp_path):
    with pytest.raises(SystemExit) as ei:
        main(["render", "--out", str(tmp_path / "a.png"), "--method", "magic"])
    assert ei.value.code == 2
    assert "invalid choice" in capsys.readouterr().err


def test_terrabench_error_in_a_subcommand_is_one_line_and_exit_2(monkeypatch, capsys):
    from experiments.cli import info
    from hybrid.errors import TerrabenchError

    def fail(*args, **kwargs):
        raise TerrabenchError("--thing must be sane, got 'x'")

    monkeypatch.setattr(info, "run", fail)
    assert main(["info", "--no-gl"]) == 2
    err = capsys.readouterr().err
    assert err == "terrabench: error: --thing must be sane, got 'x'\n"


def test_other_exceptions_in_a_subcommand_propagate(monkeypatch):
    from experiments.cli import info

    def bug(*args, **kwargs):
        raise RuntimeError("a bug, not a user error")

    monkeypatch.setattr(info, "run", bug)
    with pytest.raises(RuntimeError, match="a bug"):
        main(["info", "--no-gl"])


def test_bad_option_value_is_one_line_naming_option_value_and_limit(capsys):
    assert main(["bench", "--frames", "5000"]) == 2
    err = capsys.readouterr().err
    assert err == "terrabench: error: --frames must be an integer in [1, 1000], got '5000'\n"


def test_render_callable_without_argparse(tmp_path, ctx, capsys):
    from experiments.cli import render
    from experiments.cli.options import TerrainOptions, ViewOptions

    result = render.run(
        out=tmp_path / "r.png",
        method="raycast",
        terrain=TerrainOptions("fbm", size_samples=65),
        view=ViewOptions(size=(48, 32)),
        tile_size=32,
    )
    assert result.colour.shape == (32, 48, 3) and (tmp_path / "r.depth.npy").exists()
    assert "raycast: wrote" in capsys.readouterr().out


def test_bench_tables_are_dataframes(ctx):
    from experiments.bench_raycast import run

    tables = run(ctx, frames=1, dataset="fbm", width=48, height=32)
    ((title, df),) = tables.items()
    assert "ray caster on fbm" in title
    assert list(df["config"]) == ["naive", "maxmip", "maxmip+prepass", "maxmip float32"] and (df["steps/ray"] > 0).all()
