"""The GPU brush pass: the same heights as the CPU reference, over the touched window only, written through."""

import numpy as np
import pytest

from hybrid.gl.brush import GpuHeights
from hybrid.terrain.datasets import get_dataset
from hybrid.terrain.edits import Crater, Flatten, Raise, Smooth, apply_brush, brush_params

BRUSHES = [
    Raise((900.0, 700.0), 400.0, 50.0),
    Raise((0.0, 1920.0), 300.0, -80.0),
    Flatten((1000.0, 1000.0), 500.0, 0.8, 200.0),
    Smooth((960.0, 960.0), 600.0, 1.0),
    Crater((1500.0, 400.0), 450.0, 120.0),
    Smooth((0.0, 0.0), 300.0, 0.7),
]


@pytest.fixture
def hf():
    return get_dataset("fbm", 65)  # 64 cells of 30 m; tiles of 16 cells have borders every 480 m


@pytest.mark.parametrize("limit", [None, 24])  # one texture; 3x3 blocks of 22 samples (a GL limit of 24)
def test_gpu_brushes_equal_the_cpu_reference_in_sequence_whatever_the_blocks(ctx, hf, limit):
    cpu = hf.heights.copy()
    before = hf.heights.copy()
    gpu = GpuHeights(ctx, hf, limit)
    try:
        assert len(gpu.blocks) == (1 if limit is None else 9)
        crossed = 0
        for brush in BRUSHES:
            win = gpu.edit(brush)
            crossed += sum(not b.part(win).empty for b in gpu.blocks) > 1
            assert win == apply_brush(cpu, brush_params(brush, hf))
            tol = 1e-5 * max(1.0, float(np.abs(cpu).max()))
            np.testing.assert_allclose(hf.heights, cpu, rtol=0, atol=tol)  # the CPU copy followed
            np.testing.assert_allclose(gpu.read(), cpu, rtol=0, atol=tol)  # and the GPU's own heights
        assert np.abs(hf.heights - before).max() > 10.0
        assert limit is None or crossed >= 4  # most brushes crossed block borders, smooth ones included
    finally:
        gpu.release()


def test_height_blocks_tile_the_grid_once_and_one_texture_is_asked_for_by_name(ctx):
    from hybrid.errors import TerrabenchError
    from hybrid.gl.brush import block_starts
    from hybrid.gl.particles import ParticleParams, ParticleSystem

    for n, limit in ((16385, 16384), (65, 24), (65, 65), (8, 3), (1025, 1024)):
        starts = block_starts(n, limit)
        ends = starts[1:] + [n]
        sides = [b - a for a, b in zip(starts, ends)]
        assert starts[0] == 0 and min(sides) > 0 and max(sides) <= limit and len(starts) == -(-n // limit)
    hf = get_dataset("fbm", 33)
    gpu = GpuHeights(ctx, hf, 16)
    try:
        np.testing.assert_array_equal(gpu.read(), hf.heights)
        with pytest.raises(TerrabenchError, match=r"held in 9 height textures"):
            ParticleSystem(ctx, gpu, ParticleParams(count=16))
    finally:
        gpu.release()


def test_gpu_brush_crossing_tile_borders_changes_its_window_only(ctx, hf):
    brush = Crater((960.0, 480.0), 700.0, 90.0)  # centre on a corner of four 16-cell tiles
    before = hf.heights.copy()
    gpu = GpuHeights(ctx, hf)
    try:
        win = gpu.edit(brush)
    finally:
        gpu.release()
    assert win.i0 < 16 < win.i1 and win.j0 < 32 < win.j1 and win.j0 < 16 and win.j1 > 48
    want = before.copy()
    apply_brush(want, brush_params(brush, hf))
    np.testing.assert_allclose(hf.heights, want, rtol=0, atol=1e-3)
    changed = np.argwhere(hf.heights != before)
    assert changed[:, 0].min() >= win.i0 and changed[:, 0].max() < win.i1
    assert changed[:, 1].min() >= win.j0 and changed[:, 1].max() < win.j1
    # both sides of the border at row 16 moved: an edit across tiles is one surface
    assert np.abs(hf.heights[15:18, 30:34] - before[15:18, 30:34]).min() > 1.0


@pytest.mark.parametrize(("limit", "count"), [(24, 9), (33, 4), (64, 4), (65, 1)])
def test_height_blocks_tile_the_grid_without_overlap(ctx, hf, limit, count):
    gpu = GpuHeights(ctx, hf, limit)
    try:
        assert len(gpu.blocks) == count
        held = np.zeros(hf.heights.shape, np.int64)
        for b in gpu.blocks:
            assert b.rows <= limit and b.cols <= limit
            held[b.i0 : b.i0 + b.rows, b.j0 : b.j0 + b.cols] += 1
        assert (held == 1).all()  # every sample in exactly one block
        assert gpu.nbytes == 4 * hf.heights.size + gpu.brushes.nbytes  # float32 a sample, nothing held twice
        np.testing.assert_array_equal(gpu.read(), hf.heights)
    finally:
        gpu.release()
