"""No phantom walls: rays that start under the terrain sheet (an eye below the ground, or a ray entering the
footprint below the terrain's outer edge) see what the two-sided reference sheet shows, at every tile size,
for the ray caster, the hybrid and both raster strategies; skirts are not drawn for such rays."""

import numpy as np
import pytest
from test_hybrid import SPLIT, median_split

from hybrid.camera.view import View
from hybrid.contract import TileItem
from hybrid.gl.target import FrameTarget
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer, make_renderer
from hybrid.strategies import make_strategy
from hybrid.terrain.edges import eye_under, starts_under
from hybrid.terrain.heightfield import HeightField
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.tiletree import select_tiles

TILE_SIZES = (16, 32, 64)
SIZE = (320, 180)


def canyon(n: int = 129, spacing: float = 30.0) -> HeightField:
    """A 400 m deep canyon meandering south to north across every tile border, open at both outer edges; heights
    on a 1 cm step, as from an integer file, so the ray caster's 16-bit heights are exact (a float terrain's
    quantisation error, ~3 mm here, would move grazing hits from 3 m above the floor by about 1e-3 relative)."""
    i, j = np.mgrid[0:n, 0:n].astype(np.float64)
    axis = 0.5 * (n - 1) + 6.0 * np.sin(2 * np.pi * i / (n - 1))
    h = 400.0 * np.clip((np.abs(j - axis) - 3.0) / 4.0, 0.0, 1.0) + 5.0 * np.sin(0.3 * i) * np.cos(0.2 * j) + 5.0
    h = (np.rint(h / 0.01) * 0.01).astype(np.float32)
    return HeightField(h, spacing, (1000.0, -2000.0, 100.0), "canyon", source_step=(0.01, 0.0))


def views(hf: HeightField) -> dict:
    """Views from under the sheet (outside below the outer edge, below the ground) and one from the floor."""
    ox, oy, oz = hf.origin
    w, _ = hf.extent
    cx = ox + 0.5 * w
    g = lambda x, y: float(hf.ground_height(x, y))  # noqa: E731

    def view(eye, target):
        return View(eye, target, 60.0, *SIZE, near=0.5, far=1e5)

    return {
        # south of the terrain on the canyon's axis, 15 m up: the canyon walls' cut ends fill the sides
        "outside_floor": view([cx, oy - 300, oz + 15], [cx, oy + 3000, oz + 100]),
        # south of the terrain in line with the plateau, 120 m up: far below the rim
        "outside_wall": view([cx + 200, oy - 300, oz + 120], [cx + 200, oy + 3000, oz + 250]),
        # 100 m under the plateau, looking north across tile borders
        "below": view([cx + 600, oy + 1000, g(cx + 600, oy + 1000) - 100], [cx + 600, oy + 3000, oz + 300]),
        # 3 m above the canyon floor, looking along it across tile borders (rays from above the sheet)
        "floor": view([cx, oy + 1000, g(cx, oy + 1000) + 3], [cx + 100, oy + 3000, oz + 60]),
    }


@pytest.fixture(scope="module")
def scene(ctx):
    hf = canyon()
    vs = views(hf)
    with ReferenceRenderer(ctx, hf) as ref:
        refs = {k: ref.render(v, mode="shaded") for k, v in vs.items()}
    return hf, vs, refs


def agreement(ref, res) -> tuple[float, float]:
    """Coverage agreement with the reference and median relative distance error where both show terrain."""
    both = ref.mask & res.mask
    rel = np.abs(res.distance[both].astype(np.float64) - ref.distance[both]) / ref.distance[both]
    return float((ref.mask == res.mask).mean()), float(np.median(rel))


def pixel_dirs(view):
    rows, cols = np.mgrid[0 : view.height, 0 : view.width]
    return view.pixel_dirs_eye(rows.ravel(), cols.ravel()) @ view.rotation()


def test_the_views_look_from_under_the_sheet(scene):
    hf, vs, refs = scene
    for name, v in vs.items():
        under = starts_under(hf, v.eye, pixel_dirs(v)).reshape(v.height, v.width)
        terrain = refs[name].mask
        assert 0.3 < terrain.mean() < 0.95, name
        if name == "floor":
            assert not under.any()
        else:
            # most of what the reference shows here is the sheet's underside, seen by rays from under it
            assert (under & terrain).sum() > 0.5 * terrain.sum(), name


@pytest.mark.parametrize("tile_size", TILE_SIZES)
def test_ray_caster_draws_no_phantom_walls(ctx, scene, tile_size):
    hf, vs, refs = scene
    with make_renderer(ctx, hf, "raycast", tile_size=tile_size) as r:
        for name, v in vs.items():
            res = r.render(v, mode="shaded")
            assert res.stats.counters["capped"] == 0
            cover, med = agreement(refs[name], res)
            assert cover >= 0.999 and med <= 1e-4, (name, tile_size, cover, med)


@pytest.mark.parametrize("tile_size", TILE_SIZES)
def test_hybrid_draws_no_phantom_walls(ctx, scene, tile_size):
    hf, vs, refs = scene
    with Renderer(ctx, hf, "hybrid", tile_size=tile_size, cost_model=SPLIT, adapt=False) as r:
        for name, v in vs.items():
            r.model = median_split(r.pyramid, v)
            kinds = {r.kind(p.choice) for p in r.plan(v)}
            assert kinds == {"raster", "raycast"}, (name, tile_size, kinds)  # raster skirts face ray-cast tiles
            cover, med = agreement(refs[name], r.render(v, mode="shaded"))
            assert cover >= 0.999 and med <= 1e-3, (name, tile_size, cover, med)


@pytest.mark.parametrize("tile_size", TILE_SIZES)
def test_raster_strategies_agree_on_the_same_views(ctx, scene, tile_size):
    hf, vs, refs = scene
    for method in ("raster", "raster_gs"):
        with make_renderer(ctx, hf, method, tile_size=tile_size) as r:
            for name, v in vs.items():
                cover, med = agreement(refs[name], r.render(v, mode="shaded"))
                assert cover >= 0.999 and med <= 1e-3, (method, name, tile_size, cover, med)


@pytest.mark.parametrize("method", ["raster", "raster_gs"])
def test_skirts_are_drawn_only_for_rays_from_above_the_sheet(ctx, scene, method):
    hf, vs, _ = scene
    pyramid = TilePyramid(hf, 32)
    s = make_strategy(method, ctx, hf)
    gpu = {}
    try:
        for name in ("outside_wall", "below", "floor"):
            v = vs[name]
            sel = select_tiles(pyramid, v)
            for t in sel:
                if t.key not in gpu:
                    gpu[t.key] = s.upload(pyramid.tile(t.key))
            items = [TileItem(gpu[t.key], pyramid.tile(t.key), t) for t in sel]
            target = FrameTarget(ctx, v.width, v.height)
            try:
                target.clear()
                s.draw_tiles(target, v, items, 2 / 3, mode="shaded", skirts={t.key: 15 for t in sel})
                target.clear()  # the skirts alone, with no surface in front of them
                s.draw_skirts(target, v)
                drawn = target.read(v).mask.ravel()
            finally:
                target.release()
            under = starts_under(hf, v.eye, pixel_dirs(v))
            assert not (drawn & under).any(), name
            # rays from above the sheet still meet skirts (nothing hides them here)
            assert drawn.sum() > (200 if (~under).any() else -1), (name, drawn.sum())
    finally:
        for g in gpu.values():
            g.release()
        s.release()


def test_starts_under_follows_the_outer_edge_and_the_eye():
    h = np.tile(np.linspace(0.0, 100.0, 5, dtype=np.float32), (5, 1))  # rises eastward, 0 .. 100 m
    hf = HeightField(h, 10.0, (100.0, 200.0, 50.0))  # footprint x 100..140, y 200..240
    north = np.array([[0.0, 1.0, 0.0]])
    # from the south, horizontal: under where the south edge (50 + 2.5 m per metre east) is above the eye
    for x, z, want in ((110.0, 60.0, True), (110.0, 80.0, False), (135.0, 130.0, True), (135.0, 140.0, False)):
        assert starts_under(hf, [x, 150.0, z], north)[0] == want, (x, z)
    # a ray entering through the west edge (height 50 m): the entry point's height decides
    west_in = np.array([[1.0, 0.0, 0.5], [1.0, 0.0, -0.5]])
    assert starts_under(hf, [90.0, 220.0, 47.0], west_in).tolist() == [False, True]
    # rays that never reach the footprint
    assert not starts_under(hf, [90.0, 220.0, 0.0], np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])).any()
    # over the footprint: the eye against the triangulated ground, for every ray
    assert eye_under(hf, [120.0, 220.0, 99.0]) and not eye_under(hf, [120.0, 220.0, 101.0])
    assert starts_under(hf, [120.0, 220.0, 99.0], np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])).all()
    assert not eye_under(hf, [90.0, 220.0, -1e3])  # off the footprint: never


def test_edge_profiles_wrap_at_the_texture_limit(ctx, scene):
    """Edge profiles longer than the widest texture wrap onto more rows: the same images with the limit forced
    to 50 texels (the canyon's profiles are 129 long) as without, for rays from under the sheet."""
    from hybrid.gl.context import context_extra
    from hybrid.gl.edges import fold_profiles

    prof = np.arange(4 * 129, dtype=np.float32).reshape(4, 129)
    folded = fold_profiles(prof, 50)
    assert folded.shape == (12, 50)
    for side in range(4):
        for i in (0, 49, 50, 128):
            assert folded[side * 3 + i // 50, i % 50] == prof[side, i]
    hf, vs, _refs = scene
    images = []
    for limit in (None, 50):
        context_extra(ctx)["max_texture_size"] = limit
        try:
            with make_renderer(ctx, hf, "raycast", tile_size=32) as r:
                images.append([r.render(v, mode="shaded").distance for v in vs.values()])
        finally:
            context_extra(ctx).pop("max_texture_size", None)
    for a, b in zip(*images):
        assert np.array_equal(a, b)
