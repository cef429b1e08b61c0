"""Popping: constructed depth sequences (steady sliding, a switched patch, a crease), the image-flow gate, and
on a slow dolly flight the raster strategy without geomorphing against the same with it, each beside its floor
with the level of detail held."""

import numpy as np
import pytest

from experiments.popping import POP_MAX_FLOW_PX, image_flow, pop_pixels, popping, static_pop_pixels, temporal_errors
from hybrid.camera.view import View
from hybrid.gl.target import RenderResult


def result(distance):
    return RenderResult(np.zeros(distance.shape + (3,), np.uint8), distance.astype(np.float32))


def sequence(h=48, w=64):
    """Three reference frames of a ground whose distance grows towards the top (sky on the top rows), the
    camera moving 0.5 % closer each frame, and a method whose relative depth error slides steadily with it."""
    rows = np.arange(h, dtype=np.float64)[:, None] * np.ones((1, w))
    base = 1000.0 + 20.0 * (h - rows) + 0.3 * np.arange(w)[None, :]
    base[:6] = np.inf
    refs = [base * (1 - 0.005 * k) for k in range(3)]
    error = 1e-3 * np.sin(rows / 4.0 + np.arange(w)[None, :] / 7.0)  # a smooth error field
    frames = [r * (1 + error + 2e-4 * k) for k, r in enumerate(refs)]  # that drifts linearly in time
    return frames, refs


def test_steady_sliding_does_not_pop_and_a_switched_patch_does():
    frames, refs = sequence()
    f, r = [result(x) for x in frames], [result(x) for x in refs]
    assert pop_pixels(*f, *r) == 0
    popped = [x.copy() for x in frames]
    popped[1][20:30, 20:32] *= 1.01  # a 10 x 12 patch off by 1 % in the middle frame only
    n = pop_pixels(*[result(x) for x in popped], *r)
    assert 100 <= n <= 120
    stepped = [x.copy() for x in frames]
    stepped[2][20:30, 20:32] *= 1.01  # or switched for good from the last frame on
    assert 100 <= pop_pixels(*[result(x) for x in stepped], *r) <= 120
    crease = [x.copy() for x in frames]
    crease[1][:, 40] *= 1.01  # a one-pixel line (a crease slid over) is no patch
    assert pop_pixels(*[result(x) for x in crease], *r) == 0


def test_image_flow_gates_popping():
    v0 = View([0.0, 0.0, 100.0], [0.0, 1000.0, 0.0], 60.0, 160, 90)
    rays = v0.pixel_rays()
    t = np.where(rays[..., 2] < 0, -100.0 / np.minimum(rays[..., 2], -1e-12), np.inf)  # flat ground at z = 0
    ground = result(t)
    assert image_flow(ground, v0, v0) < 1e-9
    slow, fast = v0.moved([0.0, 0.5, 0.0]), v0.moved([0.0, 40.0, 0.0])
    assert 0 < image_flow(ground, slow, v0) < POP_MAX_FLOW_PX < image_flow(ground, fast, v0)
    same = (ground, ground, ground)
    still = popping(same, same, (v0, v0, v0))
    assert still["flow_px"] < 1e-9 and still["pop_px"] == 0
    assert np.isnan(popping(same, same, (v0, fast, fast.moved([0.0, 40.0, 0.0])))["pop_px"])


def test_colour_flicker_against_the_reference():
    rng = np.random.default_rng(1)
    r0 = RenderResult(rng.integers(0, 256, (40, 60, 3), dtype=np.uint8), np.full((40, 60), 100.0, np.float32))
    stable = temporal_errors(r0, r0, r0, r0)
    assert stable["error_flicker"] == 0 and stable["change_ratio"] == 1.0
    pop = RenderResult(r0.colour.copy(), r0.distance)
    pop.colour[20:30, 20:30] = 255 - pop.colour[20:30, 20:30]
    r1 = RenderResult(r0.colour.copy(), r0.distance)
    r1.colour[0, 0] = 0 if r1.colour[0, 0, 0] else 1  # tiny reference motion
    t = temporal_errors(r0, pop, r0, r1)
    assert t["error_flicker"] > 1.0 and t["change_ratio"] > 10


@pytest.fixture(scope="module")
def dolly(ctx):
    """A slow dolly over a 257² fbm terrain (2 m a frame), 16 frames at 320x180, and their references."""
    from hybrid.camera.flight import preset
    from hybrid.reference import ReferenceRenderer
    from hybrid.terrain.datasets import get_dataset

    hf = get_dataset("fbm", size=257)
    views = preset("dolly", hf, frames=16, width=320, height=180).views()
    ref = ReferenceRenderer(ctx, hf)
    try:
        refs = [ref.render(v) for v in views]
    finally:
        ref.release()
    return hf, views, refs


def test_raster_without_geomorphing_pops_on_a_slow_dolly(ctx, dolly):
    """Each configuration's flagged pixels beside its static floor: the same three views drawn with the middle
    frame's tiles and leaves held (``static_pop_pixels``), which no level-of-detail switch can reach."""
    from hybrid.renderer import Renderer

    hf, views, refs = dolly
    pops, static = {}, {}
    for morph, full_res in ((True, "exact"), (False, "exact"), (True, "lean")):
        with Renderer(ctx, hf, "raster", tile_size=32, morph=morph, full_res=full_res) as r:
            frames = [r.render(v, 2.0) for v in views]
            rows = [
                popping(frames[k - 1 : k + 2], refs[k - 1 : k + 2], views[k - 1 : k + 2])
                for k in range(1, len(views) - 1)
            ]
            held = [
                static_pop_pixels(r, views[k - 1 : k + 2], refs[k - 1 : k + 2], 2.0, frames[k])
                for k in range(1, len(views) - 1)
            ]
        assert all(row["flow_px"] <= POP_MAX_FLOW_PX for row in rows)  # slow enough to measure
        pops[morph, full_res] = sum(row["pop_px"] for row in rows)
        static[morph, full_res] = sum(held)
    assert pops[False, "exact"] >= 100, pops  # level switches move whole tilelets in one frame
    assert static[False, "exact"] * 10 <= pops[False, "exact"], static  # held, the same leaves do not
    assert pops[True, "exact"] * 10 <= pops[False, "exact"], pops  # geomorphing spreads them over many frames
    # full-resolution leaves dropping midpoints turn their SE and NW cells' diagonals through a morphed centre
    # post: no switch in one frame (without it, 342 px popped here); what the lean mesh flags, creases of its
    # coarser near field sliding by, it flags as much with its level of detail held
    assert pops[True, "lean"] * 10 <= pops[False, "exact"], pops
    assert pops[True, "lean"] <= static[True, "lean"] + 4, (pops, static)


def test_a_held_level_of_detail_draws_the_middle_frames_leaves(ctx, dolly):
    """``static_frames``: the middle frame redrawn with its own eye as the held one is the same image; the outer
    views keep its tiles and triangles, where the frames around it drawn freely do not."""
    from experiments.popping import static_frames
    from hybrid.renderer import Renderer

    hf, views, _ = dolly
    with Renderer(ctx, hf, "raster", tile_size=32, full_res="lean", culling=False) as r:  # every leaf counted
        middle = r.render(views[5], 2.0)
        held = static_frames(r, views[4:7], 2.0, middle)
        free = [f.stats.counters["triangles"] for f in (r.render(views[4], 2.0), r.render(views[6], 2.0))]
    assert np.array_equal(held[1].distance, middle.distance) and np.array_equal(held[1].colour, middle.colour)
    tris = {f.stats.counters["triangles"] for f in held}
    assert tris == {middle.stats.counters["triangles"]}
    assert all([p.key for p in f.plans] == [p.key for p in middle.plans] for f in held)
    assert not np.array_equal(held[0].distance, middle.distance)  # drawn from its own view
    assert set(free) != tris, free


def test_an_oracle_frame_redrawn_from_its_plans_keeps_its_measured_choices(ctx, dolly):
    """The oracle measures the tiles of a view it plans itself; given a frame's plans (as the static floor gives
    them) it draws their choices as they are, measuring nothing again."""
    from hybrid.renderer import make_renderer

    hf, views, _ = dolly
    with make_renderer(ctx, hf, "oracle", tile_size=64, oracle_repeats=1) as o:
        first = o.render(views[5], 2.0)
        choices = [(p.key, p.choice) for p in first.plans]
        again = o.render(views[6], 2.0, plans=first.plans)
    assert set(first.stats.together_ms) == {"raster", "raster_gs", "raycast"}
    assert again.stats.together_ms == {}
    assert [(p.key, p.choice) for p in again.plans] == choices
    assert again.stats.tiles == len(choices) and np.isfinite(again.distance).any()


def test_a_held_eye_that_is_not_finite_is_refused(ctx, dolly):
    from hybrid.errors import TerrabenchError
    from hybrid.renderer import Renderer

    hf, views, _ = dolly
    with Renderer(ctx, hf, "raster_gs", tile_size=32) as r:
        with pytest.raises(TerrabenchError, match="lod_eye"):
            r.render(views[0], 2.0, lod_eye=(0.0, float("nan"), 100.0))
        with pytest.raises(TerrabenchError, match="lod_eye"):
            r.render(views[0], 2.0, lod_eye=(0.0, 100.0))


@pytest.mark.parametrize("size", [(320, 180), (640, 360)])
def test_dolly_on_real_terrain_is_slow_enough_to_measure_popping(ctx, puget257, size):
    """The dolly's step follows the viewport: at either size the image moves under the popping gate."""
    from hybrid.camera.flight import preset
    from hybrid.reference import ReferenceRenderer

    views = preset("dolly", puget257, frames=4, width=size[0], height=size[1]).views()
    ref = ReferenceRenderer(ctx, puget257)
    try:
        refs = [ref.render(v) for v in views]
    finally:
        ref.release()
    flows = [image_flow(refs[k], views[k], views[k - 1]) for k in range(1, len(views))]
    assert all(0.2 < f <= POP_MAX_FLOW_PX for f in flows), flows
