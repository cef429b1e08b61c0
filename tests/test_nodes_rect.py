"""Node arrays over the grid's rectangle (``raster.rect_nodes``): at every node a tile reads, equal bit for bit to the
padded square's (``raster.nodes.square_nodes``) where measured, never below them where bounded, with memory that
follows the grid's samples; and a long thin strip drawn by the raster strategies without cracks."""

import numpy as np
import pytest

from hybrid.terrain.heightfield import HeightField
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.sidecodes import decoded_sides
from raster import rect_nodes
from raster.nodes import global_nodes, square_nodes, tile_node_block
from raster.quadtree import error_pyramid


def _rough(rows, cols, seed=3):
    """Rough terrain of rows x cols samples (metres): a random walk along x with noise across."""
    r = np.random.default_rng(seed)
    walk = np.cumsum(r.normal(0, 1, cols))
    return HeightField(
        (walk[None, :] + r.normal(0, 2, (rows, cols)) + 5 * np.sin(np.arange(rows) / 7)[:, None]).astype(np.float32),
        (10.0, 12.0),
    )


def _check(hf, n, exact_span, side_errors=True):
    """Assert the rectangular arrays against the square's at every index they hold (a superset of what tiles read):
    equal where node sides are at most exact_span cells, else effective errors never below, boxes equal and side
    codes never reading back below the exact side errors; and every tile's block likewise."""
    got, ref = global_nodes(hf, n, side_errors=side_errors), square_nodes(hf, n, side_errors=side_errors)
    assert got.cells == ref.cells and len(got.effective) == len(ref.effective)
    sides = error_pyramid(TilePyramid(hf, n).padded, got.beta).sides if side_errors else None
    top = len(ref.effective) - 1
    for g in range(top + 1):
        H, W = got.effective[g].shape
        at = (slice(0, H), slice(0, W))
        assert np.array_equal(got.zlo[g], ref.zlo[g][at]) and np.array_equal(got.zhi[g], ref.zhi[g][at]), g
        if (2 << g) <= exact_span:
            assert np.array_equal(got.effective[g], ref.effective[g][at]), g
            if side_errors and (g == top or (4 << g) <= exact_span):
                assert np.array_equal(got.sides[g], ref.sides[g][at]), g
        else:
            assert np.all(got.effective[g] >= ref.effective[g][at]), g
        if side_errors:  # codes read back (whole parents only) never below the exact side errors
            if g == top:
                read = decoded_sides(got.sides[g], None)
            else:
                p = got.effective[g + 1]
                h2, w2 = min(H // 2, p.shape[0]), min(W // 2, p.shape[1])
                read = decoded_sides(got.sides[g][: 2 * h2, : 2 * w2], p[:h2, :w2])
            assert np.all(read >= sides[g][:, : read.shape[1], : read.shape[2]]), g
    pyr = TilePyramid(hf, n)
    blocks = 0
    for level in range(pyr.max_level + 1):
        for key in pyr.keys(level):
            a, b = (tile_node_block(x, level, key.tx, key.ty, n) for x in (got, ref))
            assert np.array_equal(a[1], b[1]), key
            if exact_span >= got.cells:
                assert np.array_equal(a[0], b[0]), key
            else:
                assert np.array_equal(a[0][:, 1:3], b[0][:, 1:3]) and np.all(a[0][:, 0] >= b[0][:, 0]), key
            blocks += 1
    return blocks


@pytest.mark.parametrize(
    "rows, cols, n", [(257, 513, 32), (65, 1025, 16), (513, 65, 16), (100, 301, 16), (9, 513, 8), (3, 257, 4)]
)
def test_every_read_node_equals_the_square_computation(monkeypatch, rows, cols, n):
    monkeypatch.setattr(rect_nodes, "EXACT_SPAN", 1 << 30)
    assert _check(_rough(rows, cols), n, 1 << 30) > 1


@pytest.mark.parametrize("rows, cols, n", [(65, 513, 16), (300, 200, 16)])
def test_the_combined_form_equals_the_square_computation(monkeypatch, rows, cols, n):
    monkeypatch.setattr(rect_nodes, "EXACT_SPAN", 1 << 30)
    _check(_rough(rows, cols, seed=5), n, 1 << 30, side_errors=False)


@pytest.mark.parametrize("rows, cols, n", [(65, 513, 16), (257, 513, 32)])
def test_bounded_levels_never_below_the_square_computation(monkeypatch, rows, cols, n):
    monkeypatch.setattr(rect_nodes, "EXACT_SPAN", 32)  # nodes of 64 cells and up bounded
    hf = _rough(rows, cols, seed=7)
    _check(hf, n, 32)
    got, ref = global_nodes(hf, n), square_nodes(hf, n)
    top = got.effective[6]
    assert np.any(top > ref.effective[6][: top.shape[0], : top.shape[1]])  # a bound, not the exact value


def test_strip_node_memory_follows_its_samples():
    """A 8 x 4097 strip (a 4096² square with tiles of 64): the arrays and the build's peak memory are a few times
    the strip's own samples, not the square's 16.8 M."""
    import tracemalloc

    hf = _rough(8, 4097, seed=11)
    tracemalloc.start()
    nodes = global_nodes(hf, 64)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    held = sum(a.nbytes for arrays in (nodes.effective, nodes.zlo, nodes.zhi, nodes.sides) for a in arrays)
    assert nodes.cells == 4096 and nodes.effective[0].shape == (33, 2048)
    assert held < 4_000_000 and peak < 80_000_000, (held, peak)


def _strip_view(hf, width=320, height=180):
    """Eye 40 m above the strip's west end, looking east along it at the ground 800 m on (metres)."""
    from hybrid.camera.view import View

    ox, oy, oz = hf.origin
    mid, j = oy + 0.5 * (hf.rows - 1) * hf.spacing_y, int(800 / hf.spacing_x)
    eye = np.array([ox - 20.0, mid, oz + float(hf.heights[:, 0].max()) + 40.0])
    target = np.array([ox + j * hf.spacing_x, mid, oz + float(hf.heights[:, j].mean())])
    return View(eye, target, 30, width, height, near=1.0, far=hf.extent[0] * 2)


@pytest.mark.parametrize("rows", [8, 2])
def test_a_long_thin_strip_renders_without_cracks(ctx, rows):
    from experiments.metrics import coverage_errors
    from hybrid.reference import ReferenceRenderer
    from hybrid.renderer import Renderer

    hf = _rough(rows, 4097, seed=13)
    view = _strip_view(hf)
    with ReferenceRenderer(ctx, hf) as ref_r:
        ref = ref_r.render(view)
    assert coverage_errors(ref, ref)["ref_coverage"] > 0.02  # the strip is in the frame
    for policy in ("raster", "raster_gs", "hybrid"):
        with Renderer(ctx, hf, policy, tile_size=64) as r:
            errs = coverage_errors(r.render(view), ref)
        assert errs["crack_px"] == 0 and errs["coverage_mismatch"] <= 1e-3, (policy, errs)
        assert errs["terrain_as_sky"] <= 1e-3, (policy, errs)
