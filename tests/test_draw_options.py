"""Each strategy's draw options as a checked, frozen dataclass: given to the renderer by strategy name or as
keywords, the same frames either way; bad values and misplaced options refused by name."""

import numpy as np
import pytest

from hybrid.camera.flight import preset
from hybrid.errors import TerrabenchError
from hybrid.renderer import Renderer
from raster.options import MeshOptions, TileletOptions
from raycast.options import CastOptions


@pytest.fixture(scope="module")
def view(puget257):
    return preset("flyover", puget257, 6, 160, 90).view(2)


def test_options_by_strategy_and_by_keyword_draw_the_same_frame(ctx, puget257, view):
    given = {"raycast": CastOptions(reconstruction="bilinear", mode="height"), "raster": TileletOptions(mode="height")}
    with Renderer(ctx, puget257, "heuristic", 64, strategy_options=given) as a:
        typed = a.render(view)
        assert a.options["raycast"].reconstruction == "bilinear" and a.options["raster"].mode == "height"
    with Renderer(ctx, puget257, "heuristic", 64, reconstruction="bilinear", mode="height") as b:
        kw = b.render(view)
    with Renderer(ctx, puget257, "heuristic", 64) as c:
        default = c.render(view)
    assert {p.choice for p in typed.plans} == {"raster", "raycast"}  # both strategies drew
    assert np.array_equal(typed.colour, kw.colour) and np.array_equal(typed.distance, kw.distance)
    assert not np.array_equal(typed.colour, default.colour)  # the options took effect


def test_keywords_apply_over_the_given_options_and_per_frame(ctx, puget257, view):
    with Renderer(
        ctx, puget257, "raster", 64, strategy_options={"raster": TileletOptions(wireframe=True)}, mode="height"
    ) as r:
        assert r.options["raster"] == TileletOptions(wireframe=True, mode="height")
        wire = r.render(view)
        solid = r.render(view, wireframe=False)
        assert r.options["raster"].wireframe  # a frame's keywords do not change the renderer's options
    assert wire.mask.sum() < 0.9 * solid.mask.sum()  # edges only: pixels between them stay empty


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: TileletOptions(leaf_tau=-1.0), "leaf_tau"),
        (lambda: TileletOptions(full_res="coarse"), "full_res"),
        (lambda: TileletOptions(lod_eye=(1.0, 2.0)), "lod_eye"),
        (lambda: MeshOptions(mode="steps"), "raster mode"),
        (lambda: MeshOptions(seam_skirts=1), "seam_skirts"),
        (lambda: CastOptions(occluders="yes"), "occluders"),
        (lambda: TileletOptions().updated(recon="x"), "unknown TileletOptions option"),
    ],
)
def test_bad_option_values_are_refused_by_name(make, match):
    with pytest.raises(TerrabenchError, match=match):
        make()


def test_misplaced_options_are_refused_by_name(ctx, puget257):
    with pytest.raises(TerrabenchError, match="must be a CastOptions"):
        Renderer(ctx, puget257, "raycast", 64, strategy_options={"raycast": TileletOptions()})
    with pytest.raises(TerrabenchError, match="does not draw: tin"):
        Renderer(ctx, puget257, "raycast", 64, strategy_options={"tin": MeshOptions()})
    with pytest.raises(TerrabenchError, match="raster mode"):  # a ray-cast mode the raster tiles cannot draw
        Renderer(ctx, puget257, "hybrid", 64, mode="steps")
