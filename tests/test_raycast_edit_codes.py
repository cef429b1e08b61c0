"""The ray caster's host codes after an edit (raycast.edit_loops) equal a whole-tile quantisation and max mipmap,
and a followed GPU tile holds what a fresh upload of the edited heights holds."""

import numpy as np
import pytest

from hybrid.terrain.edits import Window
from hybrid.tiles.quantize import Q_MAX, quantize
from raycast.edit import HostCodes
from raycast.gpu_tile import code_mips
from raycast.maxmip import texel_windows
from raycast.mip_buffer import level_views

N = 64
STEP = (0.1, 0.0)


def _on_step(h):
    """Heights rounded onto STEP (float32 of offset + step * k, as a 16-bit source's loader makes them)."""
    return (STEP[1] + STEP[0] * np.rint((h.astype(np.float64) - STEP[1]) / STEP[0])).astype(np.float32)


def _random_edit(rng, h):
    """Change a random window of h in place in one of the ways edits do; the window."""
    i0, j0 = (int(v) for v in rng.integers(0, N + 1, 2))
    win = Window(i0, min(i0 + int(rng.integers(1, 12)), N + 1), j0, min(j0 + int(rng.integers(1, 12)), N + 1))
    shape, r = (win.i1 - win.i0, win.j1 - win.j0), rng.random()
    if r < 0.4:  # off the step, within or beyond the range
        h[win.slices()] += np.float32(rng.normal() * 5)
    elif r < 0.6:  # on the step again
        h[win.slices()] = _on_step(h[win.slices()])
    elif r < 0.8:
        h[win.slices()] = _on_step(rng.uniform(0, 300, shape))
    elif r < 0.9:  # flatten to one height on the step
        h[win.slices()] = _on_step(np.array(rng.uniform(0, 300)))
    else:  # the whole tile flat
        h[:] = np.float32(5.0)
        win = Window(0, N + 1, 0, N + 1)
    return win


@pytest.mark.parametrize("source_step", [STEP, None])
def test_host_codes_follow_equals_a_whole_tile_quantisation_after_every_edit(source_step):
    from raycast.edit_loops import follow_codes

    rng = np.random.default_rng(7)
    h = _on_step(rng.uniform(0, 300, (N + 1, N + 1)))
    qz = quantize(h, source_step)
    s = HostCodes.empty(N, np.uint16)
    s.params[:] = (qz.offset, qz.step, qz.base, -1)
    src = np.array(source_step if source_step else (-1.0, 0.0))
    kept = 0
    for k in range(300):
        win = _random_edit(rng, h)
        w, wins = np.array([win.i0, win.i1, win.j0, win.j1]), np.array(texel_windows(N, win))
        err, same, _levels = follow_codes(h, s.q, s.flat, s.sums, s.err, s.params, w, wins, src, k == 0, float(Q_MAX))
        want = quantize(h, source_step)
        assert tuple(s.params[:3]) == (want.offset, want.step, want.base)
        assert err == want.error
        np.testing.assert_array_equal(s.q, want.q)
        for got, full in zip(level_views(s.flat, N), code_mips(want.q), strict=True):
            np.testing.assert_array_equal(got, full)
        kept += bool(same)
    assert 50 < kept < 290  # both the window's path and the whole tile's were taken


@pytest.mark.parametrize("fmt", ["uint16", "float32"])
def test_a_followed_gpu_tile_holds_what_a_fresh_upload_holds(ctx, fmt):
    from raycast.edit import follow_tile
    from raycast.gpu_tile import prepare_heights, upload_prepared
    from raycast.mip_buffer import read_mip_buffer

    class _Tile:  # what follow_tile reads of a pyramid tile
        def __init__(self, h):
            self.heights, self.source_step = h, STEP
            self.clip, self.origin, self.spacing_xy, self.zmin, self.zmax = (0, 0, 1, 1), (0, 0, 0), (1, 1), 0, 1

    rng = np.random.default_rng(8)
    h = _on_step(rng.uniform(0, 300, (N + 1, N + 1)))
    gpu = upload_prepared(ctx, prepare_heights(h, STEP, fmt))
    try:
        for _ in range(12):
            win = _random_edit(rng, h)
            follow_tile(gpu, _Tile(h), win)
            fresh = upload_prepared(ctx, prepare_heights(h, STEP, fmt))
            assert (gpu.offset, gpu.step, gpu.base, gpu.quant_error) == (
                fresh.offset,
                fresh.step,
                fresh.base,
                fresh.quant_error,
            )
            assert gpu.heights.read() == fresh.heights.read()
            dtype = np.uint16 if fmt == "uint16" else np.float32
            for a, b in zip(
                read_mip_buffer(gpu.maxmip, N, dtype), read_mip_buffer(fresh.maxmip, N, dtype), strict=True
            ):
                np.testing.assert_array_equal(a, b)
            fresh.release()
    finally:
        gpu.release()
