"""16-bit heights: exact on Puget's 0.1 m step, bounded and reported error on float terrain, GPU against CPU."""

import numpy as np
import pytest
from test_raycast_hits import HitTarget, agreement, pixel_dirs

from hybrid.camera.view import default_view
from hybrid.terrain.datasets import fbm, puget
from hybrid.terrain.edges import starts_under
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.quantize import Q_MAX, dequantize, quantize, quantized_heights
from hybrid.tiles.tiletree import select_tiles
from raycast import RaycastStrategy
from raycast.caster import outer_faces
from raycast.cpu import cast_tile_rays


def steep():
    """A steep float terrain: 2.5 km of relief over 1.28 km at 10 m spacing."""
    return fbm(129, spacing=10.0, seed=4, amplitude=2500.0)


def test_puget_round_trip_is_exact():
    hf = puget(with_texture=False)
    assert hf.source_step == (0.1, 0.0)
    z = quantize(hf.heights, hf.source_step)
    assert z.exact and z.q.dtype == np.uint16 and int(z.q.max()) == 43798
    back = dequantize(z.q, z.offset, z.step, z.base)
    assert np.array_equal(back.view(np.uint32), hf.heights.view(np.uint32))  # bit for bit
    pyr = TilePyramid(hf, 128)
    for level in range(pyr.max_level + 1):
        for key in pyr.keys(level)[::3]:
            t = pyr.tile(key)
            zt = quantize(t.heights, t.source_step)
            assert zt.error == 0.0 and zt.base == int(np.rint(t.heights.min() / 0.1))
            assert np.array_equal(quantized_heights(t.heights, t.source_step), t.heights)
        rows, cols = pyr.tile_counts(level)
        ty, tx = np.divmod(np.arange(rows * cols), cols)
        assert not pyr.quantization_errors_at(level, tx, ty).any()


def test_float_terrain_error_is_measured_within_half_a_step_and_the_bound():
    hf = steep()
    assert hf.source_step is None
    pyr = TilePyramid(hf, 32)
    errors = []
    for level in range(pyr.max_level + 1):
        for key in pyr.keys(level):
            t = pyr.tile(key)
            z = quantize(t.heights)
            lo, hi = float(t.heights.min()), float(t.heights.max())
            assert z.offset == lo and z.step == pytest.approx((hi - lo) / Q_MAX, rel=1e-12) and z.base == 0
            assert int(z.q.min()) == 0 and int(z.q.max()) == Q_MAX
            got = np.abs(dequantize(z.q, z.offset, z.step).astype(np.float64) - t.heights).max()
            assert z.error == got > 0  # measured, reported
            assert z.error <= z.step / 2 + hi * 2.0**-24
            assert z.error <= pyr.quantization_error(key)  # the selection's bound holds
            errors.append(z.error)
    assert max(errors) < 2500.0 / Q_MAX


def test_flat_tile_and_on_step_terrain_beyond_16_bits():
    z = quantize(np.full((5, 5), 12.5, np.float32))
    assert z.step == 1.0 and not z.q.any() and z.exact and z.offset == 12.5
    h = (np.arange(25).reshape(5, 5) * 4000.0 * 0.1).astype(np.float32)  # on 0.1 m, 96000 steps apart
    z = quantize(h, (0.1, 0.0))
    assert not z.exact and z.base == 0 and z.error <= z.step / 2 + 1e-3


def test_selection_adds_the_quantisation_bound():
    hf = steep()
    pyr = TilePyramid(hf, 32)
    view = default_view(hf, 160, 90)
    for s in select_tiles(pyr, view, 2 / 3):
        if s.distance > 0:
            err = pyr.error(s.key) + pyr.quantization_error(s.key)
            assert s.projected_error == pytest.approx(err * view.pixels_per_radian / s.distance, rel=1e-12)
            assert pyr.quantization_error(s.key) > 0


@pytest.mark.parametrize("recon", ["triangles", "planes"])
def test_steep_float_frame_matches_cpu_on_the_same_heights(ctx, recon):
    hf = steep()
    pyr = TilePyramid(hf, 128)
    tile = pyr.tile(pyr.root())
    s = RaycastStrategy(ctx, hf)
    g = s.upload(tile)
    t = HitTarget(ctx, 240, 135)
    try:
        view = default_view(hf, 240, 135)
        aux, _depth, _colour, counters = t.draw(s, view, [(g, tile, None)], mode="shaded", reconstruction=recon)
        assert g.quant_error == quantize(tile.heights).error > 0
        assert counters["quant_error_max_m"] == g.quant_error
        dirs = pixel_dirs(view)
        cpu = cast_tile_rays(
            tile,
            view.eye,
            dirs,
            near=view.near,
            outer=outer_faces(tile.clip, hf),
            under=starts_under(hf, view.eye, dirs),
            reconstruction=recon,
        )
        frac, _ = agreement(aux, cpu, min(tile.spacing_xy))
        assert cpu.hit.sum() > 0.3 * view.width * view.height
        assert frac >= 0.999, f"{recon}: only {frac:.5f} of rays agree"
    finally:
        t.release()
        g.release()
        s.release()


def test_puget_frame_reports_no_quantisation_error(ctx, puget257):
    pyr = TilePyramid(puget257, 128)
    s = RaycastStrategy(ctx, puget257)
    items = [(s.upload(pyr.tile(k)), pyr.tile(k), None) for k in pyr.keys(0)]
    t = HitTarget(ctx, 160, 90)
    try:
        _aux, _d, _c, counters = t.draw(s, default_view(puget257, 160, 90), items, mode="shaded", shadows=True)
        assert counters["hits"] > 0 and counters["quant_error_max_m"] == 0.0
        assert counters["shadow_quant_error_m"] == 0.0 and counters["shadow_rays"] > 0
    finally:
        t.release()
        for g, _, _ in items:
            g.release()
        s.release()


def _numpy_quantize(h, source_step=None):
    """The quantiser written as whole-array numpy operations: (codes, offset, step, base, error)."""
    h = np.asarray(h, dtype=np.float32)
    lo, hi = float(h.min()), float(h.max())
    if source_step is not None:
        step, offset = source_step
        k = np.rint((h.astype(np.float64) - offset) / step)
        ok = (offset + step * k).astype(np.float32) == h
        if ok.all() and k.max() - k.min() <= Q_MAX and abs(k.min()) < 2**31:
            return (k - k.min()).astype(np.uint16), offset, step, int(k.min()), 0.0
    if hi == lo:
        return np.zeros(h.shape, np.uint16), lo, 1.0, 0, 0.0
    step = (hi - lo) / Q_MAX
    q = np.clip(np.rint((h.astype(np.float64) - lo) / step), 0, Q_MAX).astype(np.uint16)
    err = float(np.abs((lo + step * q.astype(np.float64)).astype(np.float32).astype(np.float64) - h).max())
    return q, lo, step, 0, err


def test_compiled_quantiser_equals_whole_array_numpy():
    """Codes, offset, step, base and error bit for bit: Puget tiles on and off its step, edited (off-step) heights,
    float terrains, flat tiles, ranges beyond 16 bits and negative heights."""
    rng = np.random.default_rng(5)
    hf = puget(size=257)
    step = hf.source_step
    cases = [(hf.heights, step), (hf.heights[:65, :65], step), (hf.heights, None)]
    edited = hf.heights.copy()
    edited[40:60, 40:60] -= rng.uniform(0, 300, (20, 20)).astype(np.float32)
    cases += [
        (edited, step),
        (fbm(129, seed=3).heights * 1000.0 - 500.0, None),
        (np.full((9, 9), 7.5, np.float32), None),
    ]
    cases += [(np.arange(81, dtype=np.float32).reshape(9, 9) * 1000.0, (0.1, 0.0)), (-hf.heights[:33, :33], step)]
    for h, s in cases:
        z = quantize(h, s)
        q, offset, st, base, err = _numpy_quantize(h, s)
        assert np.array_equal(z.q, q) and z.q.dtype == np.uint16
        assert (z.offset, z.step, z.base, z.error) == (offset, st, base, err)
