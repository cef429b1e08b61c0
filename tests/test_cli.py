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
    assert main(["render", "--dataset", "ridges", "--size-samples", "65", "--flight", "grazing", "--frame", "2",
                 "--size", "96x64", "--out", str(out), "--shading", "height"]) == 0
    assert out.exists()


@pytest.mark.parametrize("argv, match", [
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
])
def test_user_errors_exit_2(tmp_path, capsys, argv, match):
    argv = [a.replace("OUT", str(tmp_path)) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err
    assert not any(tmp_path.iterdir())                      # nothing partially written


def test_unknown_method_is_argparse_error(capsys, tmp_path):
    with pytest.raises(SystemExit) as ei:
        main(["render", "--out", str(tmp_path / "a.png"), "--method", "magic"])
    assert ei.value.code == 2
    assert "invalid choice" in capsys.readouterr().err
