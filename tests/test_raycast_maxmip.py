"""Max mipmaps: numpy reference against a brute-force definition, GPU builder (16-bit codes) level for level,
byte counts."""

import numpy as np
import pytest
from gl_memory import allocated_bytes, level_texels, object_bytes

from hybrid.errors import TerrabenchError
from hybrid.terrain.datasets import fbm
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.quantize import quantize
from raycast import RaycastStrategy
from raycast.maxmip import MaxMipBuilder, level_count, maxmip_levels, maxmip_nbytes, mip_buffer_nbytes, read_maxmip
from raycast.mip_buffer import level_starts, read_mip_buffer


def test_numpy_levels_match_definition():
    rng = np.random.default_rng(3)
    h = rng.normal(0, 100, size=(17, 17)).astype(np.float32)
    lv = maxmip_levels(h)
    assert [a.shape for a in lv] == [(16, 16), (8, 8), (4, 4), (2, 2), (1, 1)]
    for i in range(16):
        for j in range(16):
            assert lv[0][i, j] == max(h[i, j], h[i, j + 1], h[i + 1, j], h[i + 1, j + 1])
    for l in range(1, 5):
        s = 1 << l
        for i in range(16 >> l):
            for j in range(16 >> l):
                assert lv[l][i, j] == h[i * s : (i + 1) * s + 1, j * s : (j + 1) * s + 1].max()


def _codes_texture(ctx, q):
    n = q.shape[0] - 1
    ht = ctx.texture((n + 1, n + 1), 1, np.ascontiguousarray(q, dtype=np.uint16).tobytes(), dtype="u2")
    ht.filter = (ctx.NEAREST, ctx.NEAREST)
    return ht


@pytest.mark.parametrize("n", [2, 4, 64])
def test_gpu_builder_equals_numpy_every_level(ctx, puget257, n):
    # the stored levels 1..log2 N read back equal the numpy max mip of the codes, level for level
    b = MaxMipBuilder(ctx)
    rng = np.random.default_rng(n)
    cases = [
        quantize(rng.normal(-50, 300, size=(n + 1, n + 1)).astype(np.float32)).q,
        quantize(puget257.heights[: n + 1, : n + 1], puget257.source_step).q,
        rng.integers(0, 65536, size=(n + 1, n + 1)).astype(np.uint16),
    ]
    try:
        for q in cases:
            ht = _codes_texture(ctx, q)
            tex = b.build(ht, n)
            got = read_maxmip(tex, n)
            want = maxmip_levels(q)
            assert len(got) == level_count(n) - 1 == len(want) - 1 == len(level_texels(tex))
            for g, w in zip(got, want[1:]):
                assert g.dtype == np.uint16 and np.array_equal(g, w)
            ht.release()
            tex.release()
    finally:
        b.release()


def test_byte_counts(ctx, puget257):
    # the stored levels 1.. add a third of a quarter of the cells (less the 1x1 remainder)
    assert maxmip_nbytes(256) == pytest.approx(2 * 256**2 / 4 * 4 / 3, rel=1e-4)
    s = RaycastStrategy(ctx, puget257)
    try:
        pyr = TilePyramid(puget257, 128)
        tile = pyr.tile(pyr.keys(0)[0])
        g = s.upload(tile)
        # levels 1..log2 N, no more: 64² + 32² + ... + 1 texels of 2 bytes, padded to a whole word
        assert object_bytes(g.maxmip) == maxmip_nbytes(128) + 2 == 2 * (4**7 - 1) // 3 + 2 == mip_buffer_nbytes(128)
        assert level_texels(g.heights) == [129 * 129]
        assert g.nbytes == allocated_bytes(g) == object_bytes(g.heights) + object_bytes(g.maxmip)
        assert g.heights.dtype == "u2"
        levels = read_mip_buffer(g.maxmip, 128)
        want = maxmip_levels(quantize(tile.heights, tile.source_step).q)[1:]
        assert [a.shape for a in levels] == [(64 >> k, 64 >> k) for k in range(7)]
        assert all(np.array_equal(a, b) for a, b in zip(levels, want, strict=True))
        g.release()
    finally:
        s.release()


@pytest.mark.parametrize("n", [64, 128, 256])
def test_bytes_per_sample_within_target(ctx, n):
    # from the texture's and the buffer's allocated sizes: at most 2.7 bytes a held sample, max mipmap included
    hf = fbm(n + 1, seed=1)
    s = RaycastStrategy(ctx, hf)
    try:
        pyr = TilePyramid(hf, n)
        g = s.upload(pyr.tile(pyr.keys(0)[0]))
        measured = (object_bytes(g.heights) + object_bytes(g.maxmip)) / (n + 1) ** 2
        assert measured == g.bytes_per_sample == s.bytes_per_sample(n) <= 2.7
        assert 2.6 < measured
        g.release()
    finally:
        s.release()


@pytest.mark.parametrize("shape", [(16, 16), (17, 16), (13, 13), (1, 1)])
def test_bad_heights_raise(shape):
    with pytest.raises(TerrabenchError, match="heights"):
        maxmip_levels(np.zeros(shape, np.float32))


@pytest.mark.parametrize("n", [2, 4, 64, 256, 1024])
def test_buffer_level_starts_follow_the_levels_before_them(n):
    # the shader's closed form against the running sum of the level sizes (m² texels for m = n/2, n/4, ..., 1)
    sizes = [(n >> k) ** 2 for k in range(1, level_count(n))]
    assert level_starts(n) == [sum(sizes[:k]) for k in range(len(sizes))]
