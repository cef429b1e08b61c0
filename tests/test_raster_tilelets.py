"""GPU tests of the tilelet strategy: crack-free images (and holes when stitching is off), triangle counts
from GL_PRIMITIVES_GENERATED, culling that only drops what is outside, morph continuity, modes."""
import numpy as np
import pytest
from raster_helpers import border_views, holes

from hybrid.camera.view import View
from hybrid.errors import TerrabenchError
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.tiles.pyramid import TileKey


@pytest.fixture(scope="module")
def renderers(ctx, puget257, synthetic):
    out = {}
    for name in ("puget", "cliff", "spike", "staircase"):
        hf = puget257 if name == "puget" else synthetic(name)
        out[name] = (hf, Renderer(ctx, hf, "raster", tile_size=64), ReferenceRenderer(ctx, hf))
    yield out
    for _, r, ref in out.values():
        r.release()
        ref.release()


@pytest.mark.parametrize("name", ["puget", "cliff", "spike", "staircase"])
def test_crack_free_and_unstitched_holes(renderers, name):
    hf, r, ref = renderers[name]
    unstitched = 0
    for view in border_views(hf):
        rf = ref.render(view, mode="shaded")
        for morph in (True, False):
            res = r.render(view, mode="shaded", morph=morph, count_culled=True)
            assert holes(res, rf, view, hf) == 0, (name, morph)
            assert res.stats.counters["triangles"] == res.stats.counters["triangles_cpu"]
        levels = {int(g) for s in r.strategies["raster"].last_sets.values() for g in np.unique(s.global_level)}
        assert len(levels) >= 2                          # the view crosses level transitions
        bad = r.render(view, mode="shaded", stitching=False, morph=False)
        unstitched += holes(bad, rf, view, hf)
    assert unstitched >= 5, f"{name}: dropping the stitching should open cracks, found {unstitched} hole pixels"


def test_triangle_count_and_culling_only_drops_outside(renderers):
    hf, r, _ = renderers["puget"]
    w, d = hf.extent
    ox, oy, oz = hf.origin
    lo, hi = hf.height_range
    # a low view with much of each tile outside the frustum
    eye = np.array([ox + 0.3 * w, oy + 0.3 * d, oz + hi + 30])
    view = View(eye, eye + np.array([3000.0, 1000.0, -800.0]), 40, 320, 180, near=1.0, far=10 * w)
    on = r.render(view, mode="shaded", record_culling=True)
    st = r.strategies["raster"]
    assert on.stats.counters["tilelets_culled"] > 0.2 * on.stats.counters["tilelets"]
    assert on.stats.counters["triangles"] == on.stats.counters["triangles_cpu"]
    planes = view.frustum_planes_rel()
    from raster.culling import tilelet_boxes
    for key, flags in st.last_culled.items():
        if not isinstance(flags, tuple):
            continue
        cpu, gpu = flags
        assert np.count_nonzero(cpu != gpu) <= max(1, len(cpu) // 1000)
        if gpu.any():
            tile = r.tile(TileKey(*key))
            lo_b, hi_b = tilelet_boxes(tile.heights, st.last_sets[key].leaves, np.asarray(tile.origin) - view.eye, tile.spacing)
            n = planes[:, :3]
            pos = np.where(n[None] >= 0, hi_b[:, None], lo_b[:, None])
            dist = np.einsum("cpk,pk->cp", pos, n) + planes[None, :, 3]
            assert np.all(dist[gpu].min(axis=1) < 1e-2)     # really outside one plane (float32 margin)
    off = r.render(view, mode="shaded", culling=False, count_culled=True)
    assert off.stats.counters["tilelets_culled"] == 0 and off.stats.counters["triangles"] > on.stats.counters["triangles"]
    assert off.stats.counters["triangles"] == off.stats.counters["triangles_cpu"]
    assert np.array_equal(on.colour, off.colour) and np.array_equal(on.mask, off.mask)


def test_morph_continuity_across_level_switch(renderers):
    hf, r, ref = renderers["puget"]
    w, d = hf.extent
    ox, oy, oz = hf.origin
    hi = hf.height_range[1]
    leaf_tau = 8.0          # coarse leaves: a switch without morphing is plainly visible

    def view(t):
        eye = np.array([ox + 0.5 * w, oy - 0.3 * d + t, oz + hi + 1500])
        return View(eye, eye + np.array([0, 10000, -4000]), 60, 320, 180, near=1.0, far=10 * w)

    def leaves(t, morph):
        r.render(view(t), mode="shaded", leaf_tau=leaf_tau, morph=morph)
        return {k: (len(s.leaves), int(s.leaves.level.sum())) for k, s in r.strategies["raster"].last_sets.items()}

    def colour_change(a, b):
        return float(np.abs(a.colour.astype(int) - b.colour.astype(int)).mean())

    changes = {}
    for morph in (True, False):
        prev, t = leaves(0.0, morph), 0.0
        while True:
            t += 25.0
            assert t < 2000, "no level switch found"
            s = leaves(t, morph)
            if s.keys() == prev.keys() and s != prev:
                break
            prev = s
        lo_t, hi_t = t - 25.0, t
        for _ in range(10):                               # bisect the switch to a 2.5 cm eye step
            mid = 0.5 * (lo_t + hi_t)
            lo_t, hi_t = (mid, hi_t) if leaves(mid, morph) == prev else (lo_t, mid)
        a, b = view(lo_t), view(hi_t)
        ref_change = colour_change(ref.render(a, mode="shaded"), ref.render(b, mode="shaded"))
        before = r.render(a, mode="shaded", leaf_tau=leaf_tau, morph=morph)
        after = r.render(b, mode="shaded", leaf_tau=leaf_tau, morph=morph)
        changes[morph] = (colour_change(before, after), ref_change)
    margin = 0.02          # mean colour levels (0..255) over the image
    got, ref_change = changes[True]
    assert got <= ref_change + margin, changes
    popped, ref_change = changes[False]
    assert popped > 10 * (ref_change + margin), changes     # without morphing the same check fails


def test_modes_and_far_origin(ctx, renderers):
    hf, r, _ = renderers["spike"]
    view = border_views(hf)[3]
    res = r.render(view, mode="level", wireframe=True)
    colours = {tuple(c) for c in res.colour[res.mask].reshape(-1, 3)[::7]}
    assert len(colours) > 20
    base = r.render(view, mode="shaded")
    far_hf = hf.moved((5.0e6, -3.0e6, 1000.0))
    far = Renderer(ctx, far_hf, "raster", tile_size=64)
    try:
        moved = far.render(view.moved((5.0e6, -3.0e6, 1000.0)), mode="shaded")
    finally:
        far.release()
    assert np.mean(np.any(base.colour != moved.colour, axis=-1)) < 0.01
    with pytest.raises(TerrabenchError, match="mode"):
        r.render(view, mode="bogus")
    with pytest.raises(TerrabenchError, match="leaf_tau"):
        r.render(view, leaf_tau=0.0)
    with pytest.raises(TerrabenchError, match="no texture"):
        r.render(view, mode="texture")
