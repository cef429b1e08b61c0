"""Frames that mix all three candidates (raster, raster_gs, raycast): no hole along any strategy border, and a
cost model that prefers the geometry-shader path gets it chosen."""

import numpy as np

from experiments.metrics import hole_pixels_in_columns
from hybrid.camera.flight import preset
from hybrid.cost.model import CostModel
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer, make_renderer
from hybrid.strategies import candidates

SIZE = (320, 180)
FLAT = {"const": 0.0, "triangles": 0.0, "visible_triangles": 0.0, "pixels": 0.0}


def cyclic(plans):
    """The plans with their strategies cycled over the candidates by tile position (neighbours differ)."""
    for p in plans:
        p.choice = candidates()[(p.key.tx + 2 * p.key.ty) % 3]
    return plans


def test_three_strategies_in_one_frame_leave_no_hole(ctx, puget_full):
    ref = ReferenceRenderer(ctx, puget_full)
    pure = {n: make_renderer(ctx, puget_full, n, tile_size=128) for n in candidates()}
    mixed = Renderer(
        ctx,
        puget_full,
        "hybrid",
        tile_size=128,
        cost_model=CostModel(
            "flat",
            {"raster": FLAT, "raycast": {"const": 1.0, "pixels": 0.0, "surface_pixels": 0.0, "pixel_steps": 0.0}},
        ),
        adapt=False,
    )
    plan = mixed.plan
    mixed.plan = lambda view, tau: cyclic(plan(view, tau))
    fly = preset("flyover", puget_full, 6, *SIZE)
    try:
        for v in (fly.view(1), fly.view(4)):
            r = mixed.render(v)
            choices = {row["strategy"] for row in r.stats.tile_rows}
            assert choices == set(candidates())
            frames = {n: p.render(v) for n, p in pure.items()}
            want = ref.render(v)

            def holes(x, want=want):
                return (np.isfinite(want.distance) & ~np.isfinite(x.distance)) | hole_pixels_in_columns(x)

            seam = holes(r) & ~hole_pixels_in_columns(want)
            for f in frames.values():
                seam &= ~holes(f)
            assert seam.sum() <= 2, np.argwhere(seam)[:5]
            both = np.isfinite(r.distance) & np.isfinite(want.distance)
            rel = np.abs(r.distance[both] - want.distance[both]) / want.distance[both]
            assert np.median(rel) < 2e-3
    finally:
        for x in (ref, mixed, *pure.values()):
            x.release()


def test_hybrid_chooses_the_geometry_shader_path_when_the_model_says_it_is_cheapest(ctx, puget257):
    ray = {"const": 1.0, "pixels": 0.0, "surface_pixels": 0.0, "pixel_steps": 0.0}
    cheap_gs = CostModel("gs", {"raster": {**FLAT, "const": 2.0}, "raycast": ray, "raster_gs": {**FLAT, "const": 0.5}})
    no_gs = CostModel("old", {"raster": {**FLAT, "const": 2.0}, "raycast": ray})
    v = preset("flyover", puget257, 6, *SIZE).view(2)
    with Renderer(ctx, puget257, "hybrid", tile_size=64, cost_model=cheap_gs, adapt=False) as h:
        assert {p.choice for p in h.plan(v)} == {"raster_gs"}
        h.model = no_gs  # a model without raster_gs coefficients never picks it
        assert {p.choice for p in h.plan(v)} == {"raycast"}
