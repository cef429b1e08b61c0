"""GPU ray-cast hits against the numpy caster (same semantics, float64), on ordinary and degenerate rays."""

import numpy as np
import pytest

from hybrid.camera.view import View, default_view
from hybrid.gl.context import depth32f_texture
from hybrid.terrain.edges import starts_under
from hybrid.tiles.pyramid import TileKey, TilePyramid
from raycast import RaycastStrategy
from raycast.caster import outer_faces
from raycast.cpu import cast_tile_rays, texel_to_world

TOL = 1e-3  # texels (z compared in texels too: metres / spacing)


class HitTarget:
    """Colour + float32 (hit x, y, z, steps) + depth attachments: the ray caster's hit points per pixel."""

    def __init__(self, ctx, w, h):
        self.ctx, self.size = ctx, (w, h)
        self.colour = ctx.texture(self.size, 4)
        self.aux = ctx.texture(self.size, 4, dtype="f4")
        self.depth = depth32f_texture(ctx, self.size)
        self.fbo = ctx.framebuffer(color_attachments=[self.colour, self.aux], depth_attachment=self.depth)

    def draw(self, strategy, view, items, **options):
        self.fbo.clear(0, 0, 0, 0, depth=0.0)
        self.aux.write(np.full(self.size[0] * self.size[1] * 4, np.nan, np.float32).tobytes())
        self.fbo.use()
        self.ctx.enable(self.ctx.DEPTH_TEST)
        self.ctx.depth_func = ">"
        counters = strategy.draw_tiles(self, view, items, **options)
        w, h = self.size
        aux = np.frombuffer(self.aux.read(), np.float32).reshape(h, w, 4)[::-1]
        depth = np.frombuffer(self.depth.read(alignment=4), np.float32).reshape(h, w)[::-1]
        colour = np.frombuffer(self.colour.read(), np.uint8).reshape(h, w, 4)[::-1]
        return aux, depth, colour, counters

    def release(self):
        if self.ctx.fbo is self.fbo:  # never leave a deleted framebuffer bound
            self.ctx.detect_framebuffer(0).use()
        for o in (self.fbo, self.colour, self.aux, self.depth):
            o.release()


@pytest.fixture(scope="module")
def setup(ctx, puget257):
    pyr = TilePyramid(puget257, 256)
    tile = pyr.tile(pyr.root())
    s = RaycastStrategy(ctx, puget257)
    g = s.upload(tile)
    yield puget257, tile, s, g
    g.release()
    s.release()


def pixel_dirs(view):
    """World ray directions through every pixel centre, view depth 1 per unit of t (as the shader builds them)."""
    rows, cols = np.mgrid[0 : view.height, 0 : view.width]
    return view.pixel_dirs_eye(rows.ravel(), cols.ravel()) @ view.rotation()


def gpu_and_cpu(ctx, setup, view, **options):
    hf, tile, s, g = setup
    t = HitTarget(ctx, view.width, view.height)
    try:
        aux, depth, colour, counters = t.draw(s, view, [(g, tile, None)], mode="shaded", **options)
    finally:
        t.release()
    kw = {k: options[k] for k in ("reconstruction", "traversal") if k in options}
    dirs = pixel_dirs(view)
    cpu = cast_tile_rays(
        tile,
        view.eye,
        dirs,
        near=view.near,
        outer=outer_faces(tile.clip, hf),
        under=starts_under(hf, view.eye, dirs),
        **kw,
    )
    return aux, depth, colour, counters, cpu


def agreement(aux, cpu, spacing):
    """Fraction of rays hit by either side on which both hit within TOL texels (z over ``spacing`` metres a texel);
    and the per-ray agreement."""
    gh = np.isfinite(aux[..., 0]).ravel()
    gp = aux[..., :3].reshape(-1, 3).astype(np.float64)
    ok = gh == cpu.hit
    both = gh & cpu.hit
    d = np.abs(gp[both] - cpu.point[both])
    d[:, 2] /= spacing
    ok[np.nonzero(both)[0][d.max(axis=1) > TOL]] = False
    anyhit = gh | cpu.hit
    return ok[anyhit].mean() if anyhit.any() else 1.0, ok


def special_views(hf):
    w, d = hf.extent
    ox, oy, oz = hf.origin
    lo, hi = hf.height_range
    cx, cy = ox + w / 2, oy + d / 2
    gx, gy = ox + 0.3 * w, oy + 0.35 * d
    g = float(hf.ground_height(gx, gy))
    return {
        "default": default_view(hf, 320, 180),
        "north_dirx0": View([cx, oy - 0.1 * d, oz + hi + 2000], [cx, cy, oz + lo], 60, 321, 181, near=1.0, far=4e5),
        "east_diry0": View([ox - 0.1 * w, cy, oz + hi + 2000], [cx, cy, oz + lo], 60, 321, 181, near=1.0, far=4e5),
        "vertical": View(
            [cx + 13.3, cy + 7.1, oz + hi + 3000], [cx + 13.3, cy + 7.1, oz + lo], 60, 321, 181, near=1.0, far=4e5
        ),
        "grazing_inside": View([gx, gy, g + 2.0], [gx + w, gy + 0.8 * d, g + 2.0], 60, 320, 181, near=0.25, far=4e5),
        "inside_above": View(
            [gx, gy, g + 300.0], [gx + 0.3 * w, gy + 0.2 * d, g - 500], 70, 320, 180, near=0.5, far=4e5
        ),
    }


@pytest.mark.parametrize("recon", ["planes", "linear", "triangles", "bilinear"])
def test_gpu_hits_equal_cpu_hits_per_reconstruction(ctx, setup, recon):
    hf, tile = setup[0], setup[1]
    view = default_view(hf, 320, 180)
    aux, _depth, _colour, counters, cpu = gpu_and_cpu(ctx, setup, view, reconstruction=recon)
    frac, _ = agreement(aux, cpu, min(tile.spacing_xy))
    assert cpu.hit.sum() > 0.4 * view.width * view.height
    assert frac >= 0.999, f"{recon}: only {frac:.5f} of rays agree"
    assert counters["hits"] == int(np.isfinite(aux[..., 0]).sum())
    assert counters["capped"] == 0


@pytest.mark.parametrize("name", ["north_dirx0", "east_diry0", "vertical", "grazing_inside", "inside_above"])
def test_degenerate_rays(ctx, setup, name):
    hf, tile = setup[0], setup[1]
    view = special_views(hf)[name]
    dirs = pixel_dirs(view).reshape(view.height, view.width, 3)
    mid_c, mid_r = view.width // 2, view.height // 2
    special = np.zeros((view.height, view.width), bool)
    if name == "north_dirx0":
        assert np.all(dirs[:, mid_c, 0] == 0.0)
        special[:, mid_c] = True
    elif name == "east_diry0":
        assert np.all(dirs[:, mid_c, 1] == 0.0)
        special[:, mid_c] = True
    elif name == "vertical":
        assert np.all(dirs[mid_r, mid_c, :2] == 0.0)
        special[mid_r, mid_c] = True
    elif name == "grazing_inside":
        assert np.all(dirs[mid_r, :, 2] == 0.0)  # horizontal rays, 2 m above the ground
        special[mid_r, :] = True
    lo, hi = tile.aabb
    if name in ("grazing_inside", "inside_above"):
        assert np.all(view.eye >= lo) and np.all(view.eye <= hi)
    aux, depth, _colour, counters, cpu = gpu_and_cpu(ctx, setup, view)
    frac, ok = agreement(aux, cpu, min(tile.spacing_xy))
    assert frac >= 0.999, f"{name}: only {frac:.5f} of rays agree"
    assert ok.reshape(special.shape)[special].all(), f"{name}: the exactly axis-aligned rays disagree"
    if name == "vertical":
        assert cpu.hit.reshape(special.shape)[mid_r, mid_c]
    assert counters["capped"] == 0
    assert np.all(np.isfinite(depth)) and np.all((depth >= 0) & (depth <= 1))


def test_eye_below_surface_is_defined(ctx, setup):
    hf, tile = setup[0], setup[1]
    w, d = hf.extent
    ox, oy, _oz = hf.origin
    gx, gy = ox + 0.5 * w, oy + 0.45 * d
    g = float(hf.ground_height(gx, gy))
    view = View([gx, gy, g - 50.0], [gx + w, gy + 0.3 * d, g - 50.0], 60, 160, 90, near=0.5, far=4e5)
    assert starts_under(hf, view.eye, pixel_dirs(view)).all()
    aux, depth, _colour, counters, cpu = gpu_and_cpu(ctx, setup, view)
    frac, _ = agreement(aux, cpu, min(tile.spacing_xy))
    assert frac >= 0.999
    assert np.all(np.isfinite(depth)) and np.all((depth >= 0) & (depth <= 1))
    hit = np.isfinite(aux[..., 0])
    # under the sheet: a ray hits where it comes up through the surface (its underside, as the reference
    # draws it), not at the near plane; rays that stay under it miss
    assert 0.1 < hit.mean() < 0.9
    dist = view.distance_from_depth(depth)
    assert np.all(dist[hit] > 40.0)  # the surface is 50 m above the eye
    p = texel_to_world(tile, cpu.point[cpu.hit])
    assert np.abs(p[:, 2] - hf.ground_height(p[:, 0], p[:, 1])).max() < 1e-3 * min(tile.spacing_x, tile.spacing_y)
    assert counters["capped"] == 0


def test_maxmip_hits_exactly_what_naive_stepping_hits(ctx, setup, record_property):
    hf, tile = setup[0], setup[1]
    view = default_view(hf, 320, 180)
    aux_m, _, _, cm, cpu_m = gpu_and_cpu(ctx, setup, view, traversal="maxmip")
    aux_n, _, _, cn, cpu_n = gpu_and_cpu(ctx, setup, view, traversal="naive")
    # same hits on the GPU (coverage identical, points within tolerance) and on the CPU
    hm, hn = np.isfinite(aux_m[..., 0]), np.isfinite(aux_n[..., 0])
    assert np.array_equal(hm, hn)
    assert np.abs(aux_m[hm][:, :3] - aux_n[hm][:, :3]).max() <= TOL * min(tile.spacing_xy)
    assert np.array_equal(cpu_m.hit, cpu_n.hit)
    assert np.abs(cpu_m.point[cpu_m.hit] - cpu_n.point[cpu_n.hit]).max() <= 1e-6 * min(tile.spacing_xy)
    ratio = cn["steps"] / cm["steps"]
    record_property("naive_over_maxmip_steps", ratio)
    print(f"mean steps/ray: naive {cn['mean_steps']:.2f}, maxmip {cm['mean_steps']:.2f}, ratio {ratio:.2f}")
    assert ratio > 3.0
    assert cm["max_steps"] < cn["max_steps"]


@pytest.mark.parametrize("name", ["outside_below_edge", "below_ground"])
def test_rays_from_under_the_sheet_agree_with_cpu(ctx, setup, name):
    # an interior, an edge and a corner tile of a 4 x 4 split: entry walls on interior sides, none on outer ones
    hf, _, s, _ = setup
    w, d = hf.extent
    ox, oy, oz = hf.origin
    if name == "outside_below_edge":
        z = oz + float(np.median(hf.heights[0]))
        view = View(
            [ox + 0.5 * w, oy - 0.05 * d, z], [ox + 0.5 * w, oy + d, z + 0.1 * d], 60, 160, 90, near=0.5, far=4e5
        )
    else:
        gx, gy = ox + 0.4 * w, oy + 0.3 * d
        z = float(hf.ground_height(gx, gy)) - 30.0
        view = View([gx, gy, z], [gx + 0.3 * w, gy + d, z + 0.2 * d], 60, 160, 90, near=0.5, far=4e5)
    under = starts_under(hf, view.eye, pixel_dirs(view))
    assert 0.3 < under.mean() <= 1.0
    pyr = TilePyramid(hf, 64)
    hits_under = 0
    for key in (TileKey(0, 1, 1), TileKey(0, 1, 0), TileKey(0, 0, 0)):
        tile = pyr.tile(key)
        g = s.upload(tile)
        try:
            aux, _depth, _colour, counters, cpu = gpu_and_cpu(ctx, (hf, tile, s, g), view)
        finally:
            g.release()
        frac, _ = agreement(aux, cpu, min(tile.spacing_xy))
        assert frac >= 0.999, (name, key, frac)
        assert counters["capped"] == 0
        hits_under += int((cpu.hit & under).sum())
    assert hits_under > 100  # the sheet's underside is seen through these tiles
