"""Tiles of float32 metres (``heights='float32'``): the baseline that measures what 16-bit codes cost draws the
same frames as the codes where those are exact, holds what it says, and is refused where it does not apply."""

import numpy as np
import pytest

from hybrid.camera.flight import preset
from hybrid.errors import TerrabenchError
from hybrid.renderer import Renderer
from hybrid.terrain.datasets import fbm
from raycast import RaycastStrategy
from raycast.gpu_tile import code_mips, prepare_heights
from raycast.maxmip import maxmip_levels, tile_nbytes
from raycast.options import CastOptions


def test_float_mips_are_the_max_mipmap_of_the_metres():
    h = fbm(65, spacing=30.0, seed=3, amplitude=900.0).heights.astype(np.float32)
    host = prepare_heights(h, fmt="float32")
    assert host.codes.q.dtype == np.float32 and np.array_equal(host.codes.q, h)
    want = maxmip_levels(h)[1:]  # numpy's 2 x 2 maxima of the cell maxima
    got = code_mips(h)
    assert len(got) == len(want) == 6  # levels 1..log2 64
    for g, w in zip(got, want, strict=True):
        assert g.dtype == np.float32 and np.array_equal(g, w)


@pytest.mark.parametrize("flight", ["flyover", "dolly"])
def test_float32_tiles_draw_the_frames_the_exact_codes_draw(ctx, puget257, flight):
    views = [preset(flight, puget257, 6, 240, 135).view(k) for k in (1, 4)]
    frames = {}
    for fmt in ("uint16", "float32"):
        with Renderer(ctx, puget257, "raycast", tile_size=64, heights=fmt) as r:
            frames[fmt] = [r.render(v, mode="shaded") for v in views]
            held = {g.fmt: g.nbytes for _, g in r.cache.resident("raycast")}  # every resident tile's format and bytes
            assert held == {fmt: tile_nbytes(64, 4 if fmt == "float32" else 2)}
    for a, b in zip(frames["uint16"], frames["float32"], strict=True):
        hit = np.isfinite(a.distance)
        assert hit.mean() > 0.3 and np.array_equal(hit, np.isfinite(b.distance))
        rel = np.abs(a.distance[hit] - b.distance[hit]) / a.distance[hit]
        assert np.median(rel) <= 1e-6 and rel.max() < 1e-4
        assert np.mean(np.abs(a.colour.astype(int) - b.colour.astype(int)).max(axis=2) > 2) < 1e-3


def test_the_format_is_checked_and_fixed(ctx, puget257):
    with pytest.raises(TerrabenchError, match="heights must be one of uint16, float32"):
        CastOptions(heights="float16")
    with pytest.raises(TerrabenchError, match="shadows need heights='uint16'"):
        CastOptions(heights="float32", shadows=True)
    with Renderer(ctx, puget257, "raycast", tile_size=64, heights="float32") as r:
        view = preset("flyover", puget257, 4, 120, 68).view(1)
        assert np.isfinite(r.render(view).distance).any()
        with pytest.raises(TerrabenchError, match="fixed when the strategy is made"):
            r.render(view, heights="uint16")
    s = RaycastStrategy(ctx, puget257, heights="float32")
    try:
        assert s.host_prepare(puget257.heights[:65, :65]).codes.q.dtype == np.float32
    finally:
        s.release()
