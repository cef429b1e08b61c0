"""Bad input everywhere a user can reach: one clear message naming the argument, exit code 2 for the CLI,
a TerrabenchError for the API, and nothing partially written."""

import numpy as np
import pytest

from experiments.cli import main
from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import HeightField

UNWRITABLE = "/proc/terrabench-out"  # not writable, even for root


@pytest.mark.parametrize(
    "argv, match",
    [
        (["render", "--out", UNWRITABLE + "/a.png"], "does not exist"),
        (["render", "--out", "/proc/a.png"], "not a writable folder"),
        (["render", "--out", "OUT/a.png", "--method", "raycast", "--reconstruction", "cubic"], "reconstruction"),
        (["render", "--out", "OUT/a.png", "--method", "raycast", "--traversal", "teleport"], "traversal"),
        (["render", "--out", "OUT/a.png", "--method", "raster", "--shadows"], "--method raycast only"),
        (["render", "--out", "OUT/a.png", "--method", "raycast", "--wireframe"], "raster methods"),
        (["render", "--out", "OUT/a.png", "--method", "raycast", "--no-lean"], "--no-lean applies"),
        (["render", "--out", "OUT/a.png", "--method", "raycast", "--full-res", "exact"], "--full-res applies"),
        (["render", "--out", "OUT/a.png", "--method", "raster", "--show-strategy"], "mixed policy"),
        (["render", "--out", "OUT/a.png", "--tile-size", "100"], "power of two"),
        (["render", "--out", "OUT/a.png", "--dataset", "fbm", "--size-samples", "2"], "dataset size"),
        (["render", "--out", "OUT/a.png", "--method", "raster", "--shading", "sparkly"], "sparkly"),
        (["run", "OUT/missing.toml"], "no such spec"),
        (["run", "BADSPEC"], "not valid TOML"),
        (["run", "tiny", "--runs", UNWRITABLE], "not a writable folder"),
        (["report", "OUT"], "not a run folder"),
        (["calibrate", "--tau", "0"], "tau"),
        (["calibrate", "--flights", "loop"], "unknown flight"),
        (["calibrate", "--size", "0x0"], "width"),
        (["calibrate", "--frames", "0"], "--frames"),
        (["calibrate", "--save", UNWRITABLE + "/c.json"], "not a writable folder"),
        (["stress", "--scenes", "moon"], "--scenes"),
        (["stress", "--views", "sideways"], "--views"),
        (["stress", "--methods", "magic"], "--methods"),
        (["stress", "--size-samples", "5"], "--size-samples"),
        (["stress", "--out", UNWRITABLE], "not a writable folder"),
        (["bench", "--which", "gpu"], "--which"),
        (["bench", "--frames", "0"], "--frames"),
        (["info", "OUT/corrupt.tif", "--no-gl"], "not a readable raster"),
        (["info", "--dataset", "fbm", "--size-samples", "99999", "--no-gl"], "dataset size"),
        (["render", "--out", "OUT/a.png", "--dataset", "HUGE", "--spacing", "30"], "beyond ±1e+07 m"),
        (["render", "--out", "OUT/a.png", "--offset", "1e20,0,0"], "beyond the world limit"),
        (["info", "--dataset", "HUGE", "--spacing", "30", "--vertical-scale", "0", "--no-gl"], "--vertical-scale"),
        (["info", "--dataset", "HUGE", "--spacing", "30", "--vertical-scale", "-1", "--no-gl"], "must be"),
        (
            [
                "render",
                "--out",
                "OUT/a.png",
                "--dataset",
                "fbm",
                "--size-samples",
                "65",
                "--eye",
                "960,960,-500",
                "--target",
                "1500,1500,-500",
            ],
            "below the terrain surface",
        ),
        (
            [
                "render",
                "--out",
                "OUT/a.png",
                "--dataset",
                "flat",
                "--size-samples",
                "65",
                "--eye",
                "960,960,0.5",
                "--target",
                "1500,1500,0",
                "--near",
                "2",
            ],
            "within the near plane",
        ),
    ],
)
def test_cli_bad_input(tmp_path, capsys, ctx, argv, match):
    (tmp_path / "bad.toml").write_text("frames = [")
    (tmp_path / "corrupt.tif").write_bytes(b"II*\x00garbage")
    np.save(tmp_path / "huge.npy", np.full((8, 8), 1e30))
    before = set(tmp_path.rglob("*"))
    argv = [
        a.replace("OUT", str(tmp_path))
        .replace("BADSPEC", str(tmp_path / "bad.toml"))
        .replace("HUGE", str(tmp_path / "huge.npy"))
        for a in argv
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err, err
    assert set(tmp_path.rglob("*")) == before  # nothing partially written


def test_api_bad_input(ctx, puget257):
    from hybrid.camera.view import View, default_view
    from hybrid.renderer import Renderer, make_renderer
    from hybrid.tiles.pyramid import TilePyramid
    from hybrid.tiles.tiletree import select_tiles

    with pytest.raises(TerrabenchError, match="unknown policy 'magic'"):
        make_renderer(ctx, puget257, "magic")
    with pytest.raises(TerrabenchError, match=r"unknown draw option.*colour_depth"):
        make_renderer(ctx, puget257, "raycast", colour_depth=8)
    with pytest.raises(TerrabenchError, match="tau"):
        select_tiles(TilePyramid(puget257, 64), default_view(puget257), tau=float("nan"))
    with pytest.raises(TerrabenchError, match="budget"):
        Renderer(ctx, puget257, "hybrid", budget_bytes=0)
    with pytest.raises(TerrabenchError, match="unknown policy"):
        Renderer(ctx, puget257, "best")
    with pytest.raises(TerrabenchError, match="fov_y"):
        View([0, 0, 1], [1, 0, 0], float("nan"), 10, 10)
    with pytest.raises(TerrabenchError, match="up must be a non-zero vector"):
        View([0, 0, 1], [1, 0, 0], up=[0, 0, 0])
    with pytest.raises(TerrabenchError, match="spacing of 'terrain' must be a number or an"):
        HeightField(np.zeros((4, 4)), spacing=None)
    with pytest.raises(TerrabenchError, match="beyond the world limit"):
        HeightField(np.zeros((4, 4)), 30.0, origin=(1e20, 0, 0))
    with pytest.raises(TerrabenchError, match="full_res must be one of exact, lean, got 'half'"):
        Renderer(ctx, puget257, "hybrid", tile_size=64, full_res="half")
    with (
        make_renderer(ctx, puget257, "raster", tile_size=64) as r,
        pytest.raises(TerrabenchError, match="full_res must be one of exact, lean, got 'half'"),
    ):
        r.render(default_view(puget257, 32, 18), full_res="half")
    r = make_renderer(ctx, puget257, "raycast", tile_size=64)
    with pytest.raises(TerrabenchError, match="tau"):
        r.render(default_view(puget257, 32, 18), tau=-1.0)
    r.release()
    with pytest.raises(TerrabenchError, match="released"):
        r.render(default_view(puget257, 32, 18))
