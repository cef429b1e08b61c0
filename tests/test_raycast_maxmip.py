"""Max mipmaps: numpy reference against a brute-force definition, GPU builder bit for bit, byte counts."""
import numpy as np
import pytest
from gl_memory import allocated_bytes, level_texels, object_bytes

from hybrid.errors import TerrabenchError
from hybrid.tiles.pyramid import TilePyramid
from raycast import RaycastStrategy
from raycast.maxmip import MaxMipBuilder, level_count, maxmip_levels, maxmip_nbytes, read_maxmip


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
                assert lv[l][i, j] == h[i * s:(i + 1) * s + 1, j * s:(j + 1) * s + 1].max()


def test_gpu_builder_equals_numpy_bit_for_bit(ctx, puget257):
    b = MaxMipBuilder(ctx)
    rng = np.random.default_rng(0)
    cases = [rng.normal(-50, 300, size=(65, 65)).astype(np.float32), puget257.heights[:257, :257]]
    try:
        for h in cases:
            n = h.shape[0] - 1
            ht = ctx.texture((n + 1, n + 1), 1, np.ascontiguousarray(h).tobytes(), dtype="f4")
            tex = b.build(ht, n)
            got = read_maxmip(tex, n)
            want = maxmip_levels(h)
            assert len(got) == level_count(n) == len(want)
            for g, w in zip(got, want):
                assert g.dtype == np.float32 and np.array_equal(g.view(np.uint32), w.view(np.uint32))
            ht.release()
            tex.release()
    finally:
        b.release()


def test_byte_counts(ctx, puget257):
    # the coarser levels add a third of level 0 (less the 1x1 remainder)
    assert maxmip_nbytes(256) - 4 * 256 ** 2 == pytest.approx(4 * 256 ** 2 / 3, rel=1e-4)
    s = RaycastStrategy(ctx, puget257)
    try:
        pyr = TilePyramid(puget257, 128)
        tile = pyr.tile(pyr.keys(0)[0])
        g = s.upload(tile)
        assert len(level_texels(g.maxmip)) == level_count(128)         # every level allocated, no more
        assert object_bytes(g.maxmip) == maxmip_nbytes(128)
        assert g.nbytes == allocated_bytes(g) == object_bytes(g.heights) + object_bytes(g.maxmip)
        g.release()
    finally:
        s.release()


@pytest.mark.parametrize("shape", [(16, 16), (17, 16), (13, 13), (1, 1)])
def test_bad_heights_raise(shape):
    with pytest.raises(TerrabenchError, match="heights"):
        maxmip_levels(np.zeros(shape, np.float32))
