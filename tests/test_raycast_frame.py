"""Whole-frame ray casting through hybrid.renderer: reference agreement, hard terrains, shading, pre-pass, LOD."""

import numpy as np
import pytest

from hybrid.camera.flight import preset
from hybrid.camera.view import View, default_view
from hybrid.errors import TerrabenchError
from hybrid.gl.context import gl_info
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.terrain.heightfield import HeightField
from hybrid.tiles.pyramid import TilePyramid
from raycast import MODES, RaycastStrategy
from raycast.cpu import cast_rays


@pytest.fixture(scope="module")
def puget_rc(ctx, puget257):
    r = Renderer(ctx, puget257, "raycast")
    yield r
    r.release()


def compare(ref, res):
    """Coverage agreement and median relative distance difference where both show terrain."""
    cover = float((ref.mask == res.mask).mean())
    both = ref.mask & res.mask
    rel = np.abs(res.distance[both].astype(np.float64) - ref.distance[both]) / ref.distance[both]
    return cover, float(np.median(rel))


def test_registered():
    from hybrid.strategies import STRATEGIES

    assert "raycast" in STRATEGIES


def test_triangles_full_resolution_match_reference(ctx, puget257, puget_rc):
    view = default_view(puget257, 320, 180)
    ref = ReferenceRenderer(ctx, puget257).render(view, mode="shaded")
    res = puget_rc.render(view, mode="shaded", reconstruction="triangles")
    assert res.stats.tiles == 1 and res.stats.counters["capped"] == 0
    cover, med = compare(ref, res)
    assert ref.mask.mean() > 0.3
    assert cover >= 0.999, cover
    assert med <= 1e-4, med
    # same surface, same Lambert shading of the face normal: colours agree on nearly every pixel
    both = ref.mask & res.mask
    diff = np.abs(ref.colour.astype(int) - res.colour.astype(int)).max(axis=2)[both]
    assert np.mean(diff <= 2) > 0.99


@pytest.mark.parametrize("name", ["flat", "spike", "cliff", "ridges"])
def test_hard_terrains(ctx, synthetic, name):
    hf = synthetic(name)
    _w, _d = hf.extent
    _lo, _hi = hf.height_range
    views = [default_view(hf, 320, 180)]
    if name == "spike":
        i, j = int(257 * 0.55) | 1, int(257 * 0.45) | 1
        sx, sy = hf.origin[0] + j * hf.spacing_x, hf.origin[1] + i * hf.spacing_y
        base = float(np.median(hf.heights))
        views.append(View([sx - 2500, sy - 1800, base + 1500], [sx, sy, base + 1500], 50, 320, 180, near=1.0, far=1e5))
    r = Renderer(ctx, hf, "raycast")
    ref = ReferenceRenderer(ctx, hf)
    try:
        for view in views:
            res = r.render(view, mode="shaded")
            assert not np.isnan(res.distance).any()
            assert np.isfinite(res.distance[res.mask]).all()
            assert res.stats.counters["capped"] == 0 and res.stats.counters["rays"] > 0
            rr = ref.render(view, mode="shaded")
            cover, med = compare(rr, res)
            assert cover >= 0.995 and med <= 1e-3, (name, cover, med)
        if name == "spike":
            # a pixel on the spike's flank, halfway up: hit, at the reference's distance
            view = views[1]
            p = np.array([sx, sy, hf.origin[2] + float(hf.heights[i, j]) * 0.5 + base * 0.5])
            col, row, _ = view.project(p[None])[0]
            rr = ref.render(view, mode="shaded")
            res = r.render(view, mode="shaded")
            rc, cc = int(row), int(col)
            assert rr.mask[rc, cc] and res.mask[rc, cc]
            assert abs(res.distance[rc, cc] - rr.distance[rc, cc]) <= 1e-3 * rr.distance[rc, cc]
    finally:
        r.release()
        ref.release()


def test_texture_grad_closer_to_supersampled_than_plain(ctx, puget257, puget_rc):
    view = preset("flyover", puget257, frames=3, width=320, height=180).view(1)
    ss = ReferenceRenderer(ctx, puget257).render(view, mode="texture", supersample=4)
    grad = puget_rc.render(view, mode="texture")
    plain = puget_rc.render(view, mode="texture_plain")
    m = ss.mask & grad.mask & plain.mask
    assert m.mean() > 0.3
    e_grad = np.abs(grad.colour.astype(float) - ss.colour)[m].mean()
    e_plain = np.abs(plain.colour.astype(float) - ss.colour)[m].mean()
    print(f"mean |colour - supersampled|: textureGrad {e_grad:.3f}, texture {e_plain:.3f}")
    assert e_grad < e_plain


def test_modes_and_shadows(ctx, puget257, puget_rc):
    view = default_view(puget257, 160, 90)
    base = puget_rc.render(view, mode="shaded")
    images = {}
    for mode in MODES:
        res = puget_rc.render(view, mode=mode)
        assert np.array_equal(res.mask, base.mask), mode
        images[mode] = res.colour
    for a in MODES:
        for b in MODES:
            if a < b and not a.startswith("texture"):
                assert not np.array_equal(images[a], images[b]), (a, b)


LIGHT_DIR = np.array([-0.4851, 0.4851, 0.7276])


@pytest.mark.parametrize("spacing", [None, (30.0, 55.0), (55.0, 30.0)])
def test_shadow_rays_match_cpu(ctx, synthetic, spacing):
    """Shadows on the ridges terrain (30 m square cells) and, with non-square cells (x, y metres), on ridges as
    steep along y as along x (the light falls across both)."""
    hf = synthetic("ridges")
    if spacing is not None:
        h = hf.heights.astype(np.float64)
        hf = HeightField(2.0 * (h + h.T), spacing, name="ridges")
    view = default_view(hf, 160, 90)
    # tiles of 64 cells, all at full resolution: each tile places its shadow rays' origins on the whole grid
    r = Renderer(ctx, hf, "raycast", tile_size=64)
    try:
        lit = r.render(view, tau=0.01, mode="shaded")
        sh = r.render(view, tau=0.01, mode="shaded", shadows=True)
    finally:
        r.release()
    assert np.array_equal(sh.mask, lit.mask)
    assert sh.stats.counters["shadow_rays"] > 0 and sh.stats.counters["shadow_capped"] == 0
    assert not (sh.colour.astype(int).sum(axis=2) > lit.colour.astype(int).sum(axis=2) + 1).any()
    darker = (sh.colour.astype(int).sum(axis=2) < lit.colour.astype(int).sum(axis=2) - 2) & lit.mask
    frac = darker.sum() / lit.mask.sum()
    assert 0.02 < frac < 0.9, frac
    # CPU shadow rays from the GPU's hit points (recovered from depth) toward the light, whole terrain
    rows, cols = np.nonzero(lit.mask)
    dirs = view.pixel_rays(rows, cols)
    pts = view.eye + dirs * lit.distance[rows, cols, None]
    tex = np.stack(
        [
            (pts[:, 0] - hf.origin[0]) / hf.spacing_x,
            (pts[:, 1] - hf.origin[1]) / hf.spacing_y,
            pts[:, 2] - hf.origin[2],
        ],
        1,
    )
    h = hf.heights.astype(np.float64)
    i = np.clip(np.floor(tex[:, 1]).astype(int), 0, hf.rows - 2)
    j = np.clip(np.floor(tex[:, 0]).astype(int), 0, hf.cols - 2)
    fi, fj = tex[:, 1] - i, tex[:, 0] - j
    lower = fj >= fi
    gx = np.where(lower, h[i, j + 1] - h[i, j], h[i + 1, j + 1] - h[i + 1, j]) / hf.spacing_x
    gy = np.where(lower, h[i + 1, j + 1] - h[i, j + 1], h[i + 1, j] - h[i, j]) / hf.spacing_y
    n = np.stack([-gx, -gy, np.ones_like(gx)], 1)
    cosl = (n @ LIGHT_DIR) / np.linalg.norm(n, axis=1)
    clear = cosl > 0.1  # lit side, away from the self-shadow terminator
    o = tex[clear] + np.array([0, 0, 1e-3 * max(hf.spacing_x, hf.spacing_y) + 0.01])
    L = np.array([LIGHT_DIR[0] / hf.spacing_x, LIGHT_DIR[1] / hf.spacing_y, LIGHT_DIR[2]])
    lo, hi = hf.height_range
    res = cast_rays(hf.heights, (hf.cols - 1, hf.rows - 1), (lo, hi), o, np.tile(L, (len(o), 1)), outer=15)
    cpu_shadow = res.status != 0
    gpu_shadow = darker[rows[clear], cols[clear]]
    assert cpu_shadow.sum() > 50
    assert np.mean(cpu_shadow == gpu_shadow) > 0.97


def test_prepass_same_image_fewer_rays(ctx, puget_full):
    view = preset("flyover", puget_full, frames=5, width=320, height=180).view(2)
    r = Renderer(ctx, puget_full, "raycast")
    try:
        a = r.render(view, mode="shaded", prepass=False)
        b = r.render(view, mode="shaded", prepass=True)
    finally:
        r.release()
    assert a.stats.tiles > 4
    assert np.array_equal(a.mask, b.mask)
    assert np.mean(np.all(a.colour == b.colour, axis=2)) > 0.999
    assert np.allclose(a.distance[a.mask], b.distance[b.mask], rtol=1e-6)
    assert b.stats.counters["rays"] < a.stats.counters["rays"]
    assert b.stats.counters["hits"] == a.mask.sum()
    r = Renderer(ctx, puget_full, "raycast")  # no choice made: the device's default
    try:
        c = r.render(view, mode="shaded")
    finally:
        r.release()
    software = gl_info(ctx).is_software  # off on a CPU rasterizer, on on a GPU
    assert c.stats.counters["rays"] == (a if software else b).stats.counters["rays"]
    assert np.array_equal(c.mask, a.mask)


def test_lod_fewer_steps_close_image(ctx, puget_full):
    view = default_view(puget_full, 320, 180)
    r = Renderer(ctx, puget_full, "raycast")
    ref = ReferenceRenderer(ctx, puget_full)
    try:
        full = r.render(view, tau=0.05, mode="level")
        lod = r.render(view, tau=0.05, mode="level", lod=1.0)
        rr = ref.render(view, mode="shaded")
    finally:
        r.release()
        ref.release()
    assert lod.stats.counters["mean_steps"] < full.stats.counters["mean_steps"]
    assert not np.array_equal(full.colour, lod.colour)  # coarser levels are used inside tiles
    cover, med = compare(rr, lod)
    assert cover >= 0.99 and med <= 2e-3, (cover, med)


def test_bad_options(ctx, puget257, synthetic):
    s = RaycastStrategy(ctx, puget257)
    try:
        for kw, word in [
            ({"reconstruction": "voxels"}, "reconstruction"),
            ({"traversal": "fast"}, "traversal"),
            ({"mode": "fancy"}, "mode"),
            ({"lod": 1.0, "traversal": "naive"}, "lod"),
            ({"lod": -1.0}, "lod"),
            ({"max_steps": 0}, "max_steps"),
            ({"shadows": 1}, "shadows"),
            ({"colour": "red"}, "unknown"),
        ]:
            with pytest.raises(TerrabenchError, match=word):
                s.draw_tiles(None, default_view(puget257, 32, 18), [], **kw)
    finally:
        s.release()
    with pytest.raises(TerrabenchError, match="texture"):
        RaycastStrategy(ctx, synthetic("flat"), mode="texture")


def test_step_cap_counts_capped_rays(ctx, puget257):
    s = RaycastStrategy(ctx, puget257)
    pyr = TilePyramid(puget257, 256)
    tile = pyr.tile(pyr.root())
    g = s.upload(tile)
    from hybrid.gl.target import FrameTarget

    view = default_view(puget257, 160, 90)
    t = FrameTarget(ctx, 160, 90)
    try:
        t.clear()
        t.use()
        c = s.draw_tiles(t, view, [(g, tile, None)], mode="shaded", max_steps=4)
        res = t.read(view)
    finally:
        t.release()
        g.release()
        s.release()
    assert c["capped"] > 0 and c["max_steps"] == 4
    assert c["hits"] == res.mask.sum()
    assert c["hits"] + c["capped"] <= c["rays"]


@pytest.mark.parametrize("recon", ["triangles", "bilinear", "planes"])
def test_a_view_with_no_ray_under_the_sheet_draws_as_the_exact_bounds_do(ctx, puget257, recon, monkeypatch):
    """From over the footprint, above the ground, the caster takes no ray to start under the sheet and steps
    level-0 cells against their parents' bounds; forced to test every ray and every cell's own bound (as for a
    view that may have rays under the sheet), it draws the same frames and takes no fewer steps."""
    import raycast.caster as rc
    from hybrid.terrain.edges import may_start_under

    views = preset("flyover", puget257, 3, 320, 180).views()
    assert not any(may_start_under(puget257, v.eye) for v in views)
    with Renderer(ctx, puget257, "raycast", reconstruction=recon) as r:
        fast = [r.render(v, 2 / 3, stats=True) for v in views]
        monkeypatch.setattr(rc, "may_start_under", lambda hf, eye: True)
        exact = [r.render(v, 2 / 3, stats=True) for v in views]
    for a, b in zip(fast, exact):
        assert np.array_equal(a.mask, b.mask)
        np.testing.assert_allclose(a.distance[a.mask], b.distance[b.mask], rtol=1e-6)
        assert a.stats.row()["steps"] == b.stats.row()["steps"]


def test_a_view_from_outside_or_under_the_footprint_may_start_rays_under(puget257):
    from hybrid.terrain.edges import may_start_under

    cx, cy = puget257.origin[0] + 128 * puget257.spacing_x, puget257.origin[1] + 128 * puget257.spacing_y
    ground = float(puget257.sample_triangles(128.0, 128.0)) + puget257.origin[2]
    assert not may_start_under(puget257, (cx, cy, ground + 100.0))
    assert may_start_under(puget257, (cx, cy, ground - 100.0))
    assert may_start_under(puget257, (puget257.origin[0] - 500.0, cy, ground + 5000.0))
