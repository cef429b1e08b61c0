"""Non-square ground spacing (spacing_x != spacing_y) through the whole pipeline: tiles and their boxes, cost
features, every drawing method against the reference, GPU ray-cast hits against the CPU caster, and .npz files."""

import numpy as np
import pytest
from spacing_helpers import NON_SQUARE, terrain, views
from test_raycast_hits import HitTarget, agreement, pixel_dirs

from experiments.metrics import near_silhouettes
from hybrid.camera.view import View
from hybrid.cost.features import feature_columns, tile_features
from hybrid.cost.model import CostModel
from hybrid.cost.planner import plan_frame
from hybrid.errors import TerrainLoadError
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.terrain.heightfield import HeightField
from hybrid.terrain.loaders import load_terrain, save_npz
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.tiletree import select_tiles
from raster.nodes import global_nodes, tile_levels, tile_node_block
from raster.tilelets import read_leaves
from raycast import RaycastStrategy
from raycast.caster import outer_faces
from raycast.cpu import cast_tile_rays

TILE = 16
METHODS = ("raster", "raster_gs", "raycast", "fullres", "tin", "hybrid")


# --- tiles and features (no GL) -------------------------------------------------------------------------------
@pytest.mark.parametrize("spacing", NON_SQUARE)
def test_tiles_span_their_cells_per_axis(spacing):
    hf = terrain(spacing)
    sx, sy = spacing
    pyr = TilePyramid(hf, TILE)
    assert hf.extent == (128 * sx, 128 * sy)
    for level in range(pyr.max_level + 1):
        keys = pyr.keys(level)
        lo, hi = pyr.aabbs([k.level for k in keys], [k.tx for k in keys], [k.ty for k in keys])
        cells = TILE << level
        for n, k in enumerate(keys):
            t = pyr.tile(k)
            assert (t.spacing_x, t.spacing_y) == (sx * (1 << level), sy * (1 << level))
            assert t.origin[:2] == (k.tx * cells * sx, k.ty * cells * sy)
            assert t.clip == (k.tx * cells * sx, k.ty * cells * sy, (k.tx + 1) * cells * sx, (k.ty + 1) * cells * sy)
            assert np.array_equal(lo[n], pyr.aabb(k)[0]) and np.array_equal(hi[n], pyr.aabb(k)[1])
            # the box bounds every level-0 sample under the tile, at its world position
            i, j = np.mgrid[k.ty * cells : (k.ty + 1) * cells + 1, k.tx * cells : (k.tx + 1) * cells + 1]
            p = hf.world_of(i, j)
            assert np.all(p >= lo[n] - 1e-9) and np.all(p <= hi[n] + 1e-9)
        # the level's tiles cover the terrain's rectangle exactly once
        area = float(np.prod(hi[:, :2] - lo[:, :2], axis=1).sum())
        assert np.isclose(area, hf.extent[0] * hf.extent[1], rtol=1e-12)


def test_slab_cells_count_cells_along_the_ray_heading():
    """A tile's slab run (metres) counted in cells along the ray's heading: x steps of spacing_x, y of spacing_y."""
    hf = terrain(NON_SQUARE[0])
    view = views(hf)[3]
    pyr = TilePyramid(hf, TILE)
    sel = select_tiles(pyr, view, tau=1.5)
    cells = feature_columns(pyr, view, sel, np.ones(len(sel)))["slab_cells"]
    assert np.allclose(cells, [tile_features(pyr, view, s, 1.0).slab_cells for s in sel], rtol=1e-9)
    assert len({s.key.level for s in sel}) >= 2
    for s, c in zip(sel, cells):
        lo, hi = pyr.aabb(s.key)
        d = 0.5 * (lo + hi) - view.eye
        k = 1 << s.key.level
        run = (hi[2] - lo[2]) * np.hypot(d[0], d[1]) / abs(d[2])
        heading = d[:2] / np.hypot(d[0], d[1])
        want = min(run * np.hypot(heading[0] / (30.0 * k), heading[1] / (55.0 * k)), TILE * np.sqrt(2.0))
        assert np.isclose(c, want, rtol=1e-9)


@pytest.mark.parametrize("spacing", NON_SQUARE)
def test_front_to_back_order_starts_under_the_eye(spacing):
    """Looking down from anywhere over the terrain, the first tile of the front-to-back order is the one below the
    eye: the quadtree traversal splits each tile at its centre in metres, x and y each in its own spacing."""
    hf = terrain(spacing)
    pyr = TilePyramid(hf, TILE)
    w, d = hf.extent
    lo, hi = hf.height_range
    for fx in np.linspace(0.03, 0.97, 9):
        for fy in np.linspace(0.03, 0.97, 9):
            x, y = fx * w, fy * d
            view = View([x, y, hi + 300.0], [x + 10.0, y + 20.0, lo], 60, 160, 90, near=1.0, far=1e5)
            sel = select_tiles(pyr, view)
            x0, y0, x1, y1 = pyr.clip(sel[0].key)
            assert x0 <= x <= x1 and y0 <= y <= y1, (fx, fy, sel[0].key)


def test_npz_stores_and_reads_both_spacings(tmp_path):
    hf = terrain(NON_SQUARE[0])
    save_npz(hf, tmp_path / "t.npz")
    back = load_terrain(tmp_path / "t.npz")
    assert (back.spacing_x, back.spacing_y) == (30.0, 55.0) and back.spacing == (30.0, 55.0)
    assert np.array_equal(back.heights, hf.heights)
    square = HeightField(hf.heights, 12.5)
    save_npz(square, tmp_path / "s.npz")
    assert load_terrain(tmp_path / "s.npz").spacing == 12.5
    np.savez(tmp_path / "one.npz", heights=hf.heights, spacing=np.float64(7.0))  # one number: square cells
    assert (load_terrain(tmp_path / "one.npz").spacing_x, load_terrain(tmp_path / "one.npz").spacing_y) == (7.0, 7.0)
    np.savez(tmp_path / "bad.npz", heights=hf.heights, spacing=np.ones(3))
    with pytest.raises(TerrainLoadError, match=r"bad\.npz.*spacing"):
        load_terrain(tmp_path / "bad.npz")
    np.savez(tmp_path / "neg.npz", heights=hf.heights, spacing=np.array([30.0, -55.0]))
    with pytest.raises(TerrainLoadError, match=r"neg\.npz.*spacing y"):
        load_terrain(tmp_path / "neg.npz")


# --- drawing (GL) ---------------------------------------------------------------------------------------------
def split_model(pixels: float) -> CostModel:
    """Raster for tiles whose box covers fewer than ``pixels`` (1e-3 ms a pixel), ray casting (a constant) for the
    rest, so a frame really mixes both strategies."""
    return CostModel(
        "split",
        {
            "raster": {"const": 0.0, "triangles": 0.0, "visible_triangles": 0.0, "pixels": 1e-3},
            "raycast": {"const": 1e-3 * pixels, "pixels": 0.0, "surface_pixels": 0.0, "pixel_steps": 0.0},
        },
    )


@pytest.fixture(scope="module")
def references(ctx):
    """{(spacing, drawn spacing): [reference frame per view]}: each non-square terrain, and the same heights with
    square cells of spacing_x and with the two spacings swapped, all under the non-square terrain's views."""
    out = {}
    for spacing in NON_SQUARE:
        vs = views(terrain(spacing))
        for sp in (spacing, (spacing[0], spacing[0]), spacing[::-1]):
            with ReferenceRenderer(ctx, terrain(sp)) as ref:
                out[(spacing, sp)] = [ref.render(v, mode="shaded") for v in vs]
                if sp == spacing:
                    out[(spacing, "texture")] = [ref.render(v, mode="texture") for v in vs]
    return out


@pytest.mark.parametrize("spacing", NON_SQUARE)
def test_the_views_tell_the_spacings_apart(references, spacing):
    """Drawing a non-square terrain with one spacing for both axes (or the two swapped) changes coverage far beyond
    the 0.1-0.2 % the methods below may differ by, in every view: those tests fail if a method does so."""
    own = references[(spacing, spacing)]
    for other in ((spacing[0], spacing[0]), spacing[::-1]):
        agree = [float((a.mask == b.mask).mean()) for a, b in zip(own, references[(spacing, other)])]
        assert max(agree) < 0.99, (other, agree)
    assert all(0.25 < f.mask.mean() < 0.8 for f in own)


# coverage agreement with the reference (whole frame): at the default tau, and at 1.5 px where most tiles are drawn
# from pyramid levels 1 and 2 (silhouettes move by up to the larger bound)
COVER = {2 / 3: 0.999, 1.5: 0.998}


@pytest.mark.parametrize("spacing", NON_SQUARE)
@pytest.mark.parametrize("method", METHODS)
def test_every_method_draws_the_reference_surface(ctx, references, spacing, method):
    """Each method covers the reference's pixels at the depth tolerances of the square-spacing tests (median
    relative depth error 1e-4 for ray casting, 2e-3 with level of detail) and maps the texture as the reference
    does (texel rows north, columns east); at tau 0.05 px all but the TIN draw the reference's surface with its
    shading (normals from x and y slopes in metres); the hybrid mixes both strategies in every frame."""
    hf = terrain(spacing)
    r = Renderer(
        ctx, hf, method, tile_size=TILE, cost_model=split_model(1.0) if method == "hybrid" else None, adapt=False
    )
    if method == "tin":
        r.strategies["tin"].max_error, r.strategies["tin"].preserve_border = 1.0, True  # a TIN within 1 m
    try:
        for view, ref, ref_tex in zip(views(hf), references[(spacing, spacing)], references[(spacing, "texture")]):
            tex = r.render(view, mode="texture")
            ok = tex.mask & ref_tex.mask & ~near_silhouettes(ref_tex.distance)
            diff = np.abs(tex.colour.astype(int) - ref_tex.colour.astype(int)).max(axis=2)[ok]
            assert diff.mean() < 1.0 and np.percentile(diff, 99) <= 3, (method, diff.mean(), np.percentile(diff, 99))
            for tau, bar in COVER.items():
                if method == "hybrid":  # about half the tiles each way: split at the median box footprint
                    px = [p.features.pixels for p in plan_frame(r.pyramid, view, split_model(1.0), tau=tau)]
                    r.model = split_model(float(np.median(px)))
                res = r.render(view, tau=tau, mode="shaded", maps=method == "hybrid")
                both = res.mask & ref.mask
                rel = np.abs(res.distance[both] - ref.distance[both]) / ref.distance[both]
                cover = float((res.mask == ref.mask).mean())
                assert cover >= bar, (method, tau, cover)
                if method == "raycast" and tau < 1:
                    assert np.median(rel) <= 1e-4 and res.stats.counters["capped"] == 0
                else:
                    assert np.median(rel) < 2e-3, (method, tau, np.median(rel))
                if method == "hybrid":
                    smap = res.maps["strategy"]
                    assert (smap == 1).any() and (smap == 2).any()
            if method != "tin":  # at full resolution: the reference's surface, normals and shading
                fine = r.render(view, tau=0.05, mode="shaded")
                both = fine.mask & ref.mask
                rel = np.abs(fine.distance[both] - ref.distance[both]) / ref.distance[both]
                assert (fine.mask == ref.mask).mean() > 0.999 and np.percentile(rel, 99) <= 1e-4
                ok = both & ~near_silhouettes(ref.distance)
                diff = np.abs(fine.colour.astype(int) - ref.colour.astype(int)).max(axis=2)[ok]
                assert np.mean(diff <= 2) > 0.99, (method, np.mean(diff <= 2))
    finally:
        r.release()


@pytest.mark.parametrize("spacing", NON_SQUARE)
def test_gpu_leaf_selection_measures_node_boxes_per_axis(ctx, spacing):
    """Every leaf the GPU selection drew is a node that does not split while its parent does: a node splits when
    its effective error (m) times K / tau exceeds the distance to its box, the node's square grown by its side,
    x in the tile's spacing_x and y in its spacing_y (float32 on the GPU: 1e-4 relative slack)."""
    hf = terrain(spacing)
    tau = 2.0
    with Renderer(ctx, hf, "raster_gs", tile_size=TILE) as r:
        nodes = global_nodes(hf, TILE, r.strategies["raster_gs"].beta)
        top = tile_levels(TILE) - 1
        checked, levels = 0, set()
        for view in views(hf)[:2]:
            r.render(view, tau=tau, culling=False)
            k_tau = view.pixels_per_radian / tau
            for p in r.plan(view, tau=tau):
                tile = r.pyramid.tile(p.key)
                data, offsets = tile_node_block(nodes, p.key.level, p.key.tx, p.key.ty, TILE)
                rel = np.asarray(tile.origin) - view.eye

                def err_and_distance(m, a, b, data=data, offsets=offsets, rel=rel, tile=tile, k_tau=k_tau):
                    side, size = TILE >> (m + 1), 2 << m
                    e, zlo, zhi, _ = data[offsets[m] + (a + 1) * (side + 2) + (b + 1)]
                    lo = rel + [(b - 1) * size * tile.spacing_x, (a - 1) * size * tile.spacing_y, zlo]
                    hi = rel + [(b + 2) * size * tile.spacing_x, (a + 2) * size * tile.spacing_y, zhi]
                    return e * k_tau, np.linalg.norm(np.maximum(np.maximum(lo, -hi), 0.0))

                leaves = read_leaves(r.strategies["raster_gs"], r.cache.entries[("raster_gs", p.key)])
                for m, i0, j0 in zip(leaves["level"], leaves["i0"], leaves["j0"]):
                    a, b = int(i0) >> (int(m) + 1), int(j0) >> (int(m) + 1)
                    levels.add(int(m))
                    if 1 <= m < top:
                        e, d = err_and_distance(int(m), a, b)
                        assert e <= d * (1 + 1e-4), (p.key, m, a, b, e, d)
                    if m + 1 < top:
                        e, d = err_and_distance(int(m) + 1, a // 2, b // 2)
                        assert e > d * (1 - 1e-4), (p.key, m + 1, a // 2, b // 2, e, d)
                        checked += 1
        assert checked > 500 and len(levels) >= 2, (checked, levels)


@pytest.mark.parametrize("spacing", NON_SQUARE)
def test_gpu_ray_caster_hits_equal_cpu_hits(ctx, spacing):
    """Per tile of every level (spacing scaled by 2^level), the GPU's hit points in tile texels equal the numpy
    caster's for every pixel ray of two views."""
    hf = terrain(spacing)
    pyr = TilePyramid(hf, TILE)
    s = RaycastStrategy(ctx, hf)
    keys = [pyr.root(), pyr.keys(2)[2], pyr.keys(1)[9], pyr.keys(0)[20], pyr.keys(0)[45]]
    try:
        for key in keys:
            tile = pyr.tile(key)
            g = s.upload(tile)
            try:
                hits = 0
                for view in views(hf, 160, 90)[::3]:
                    t = HitTarget(ctx, view.width, view.height)
                    try:
                        aux, _, _, counters = t.draw(s, view, [(g, tile, None)], mode="shaded")
                    finally:
                        t.release()
                    cpu = cast_tile_rays(
                        tile, view.eye, pixel_dirs(view), near=view.near, outer=outer_faces(tile.clip, hf)
                    )
                    frac, _ = agreement(aux, cpu, min(tile.spacing_xy))
                    assert frac >= 0.999, (key, frac)
                    assert counters["capped"] == 0
                    hits += int(cpu.hit.sum())
                assert hits > 100, key
            finally:
                g.release()
    finally:
        s.release()
