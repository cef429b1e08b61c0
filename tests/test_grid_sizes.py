"""Grids wider or taller than the GL's texture limit: with the limit forced small (the code reads it from the
context, and a test may lower it), every method draws a grid one sample past it, and the reference agrees with
an exact CPU intersection of its triangles at sampled pixels; the block layout covers every cell once; a stored
grid streams its blocks out of core into the same image; a colour texture past the limit is resampled to fit."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from experiments.metrics import near_silhouettes
from hybrid.camera.view import View
from hybrid.gl.context import context_extra
from hybrid.gl.textures import fit_texture
from hybrid.reference import ReferenceRenderer
from hybrid.reference_blocks import reference_blocks
from hybrid.renderer import make_renderer
from hybrid.terrain.heightfield import HeightField

LIMIT = 128
METHODS = ("reference", "raycast", "raster", "raster_gs", "hybrid", "fullres", "tin")


def hills(rows: int, cols: int, spacing: float = 30.0) -> HeightField:
    """Rolling hills on a 1 cm height step (exact in the ray caster's 16-bit heights)."""
    i, j = np.mgrid[0:rows, 0:cols].astype(np.float64)
    h = 60 * np.sin(j / 9.0) * np.cos(i / 7.0) + 40 * np.sin((i + 2 * j) / 23.0) + 0.3 * j + 100.0
    h = (np.rint(h / 0.01) * 0.01).astype(np.float32)
    return HeightField(h, spacing, (500.0, -300.0, 20.0), f"hills{cols}x{rows}", source_step=(0.01, 0.0))


def along(hf: HeightField, width: int = 160, height: int = 96) -> View:
    """From above the south-west corner, looking along the grid's longer side."""
    ox, oy, oz = hf.origin
    w, d = hf.extent
    lo, hi = hf.height_range
    top = oz + hi + 0.06 * max(w, d)
    target = (ox + 0.7 * w, oy + 0.5 * d, oz + lo) if w >= d else (ox + 0.5 * w, oy + 0.7 * d, oz + lo)
    return View((ox + 0.02 * w, oy + 0.02 * d, top), target, 60.0, width, height, near=1.0, far=4 * max(w, d))


def cpu_distances(hf: HeightField, view: View, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Eye-to-surface distance (metres; inf for a miss) of the pixel-centre rays, by intersecting every triangle
    of the grid (two a cell, SW-NE diagonal) in float64 (Moller-Trumbore)."""
    i, j = np.mgrid[0 : hf.rows, 0 : hf.cols]
    P = np.stack(
        [
            hf.origin[0] + j * hf.spacing_x,
            hf.origin[1] + i * hf.spacing_y,
            hf.origin[2] + hf.heights.astype(np.float64),
        ],
        axis=-1,
    )
    a, b, c, d = P[:-1, :-1], P[:-1, 1:], P[1:, 1:], P[1:, :-1]
    tris = np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3), np.stack([a, c, d], -2).reshape(-1, 3, 3)])
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    dirs = view.pixel_rays(rows, cols)
    out = np.full(len(dirs), np.inf)
    s = view.eye - v0
    for k, D in enumerate(dirs):
        p = np.cross(D, e2)
        det = np.einsum("ij,ij->i", e1, p)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = (q @ D) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > view.near)
        if hit.any():
            out[k] = t[hit].min()
    return out


@pytest.fixture
def small_limit(ctx):
    context_extra(ctx)["max_texture_size"] = LIMIT
    yield LIMIT
    context_extra(ctx).pop("max_texture_size", None)


def test_the_exact_track_walk_agrees_with_every_triangle():
    from experiments.exact_hits import exact_distances

    hf = hills(33, 129)
    view = along(hf)
    rng = np.random.default_rng(5)
    rows, cols = rng.integers(0, view.height, 300), rng.integers(0, view.width, 300)
    brute, walked = cpu_distances(hf, view, rows, cols), exact_distances(hf, view, rows, cols)
    assert np.array_equal(np.isfinite(brute), np.isfinite(walked)) and np.isfinite(brute).sum() > 50
    hit = np.isfinite(brute)
    assert np.abs(brute[hit] - walked[hit]).max() < 1e-9 * brute[hit].max()


def test_blocks_cover_every_cell_once():
    for rows, cols, side in ((33, 129, 128), (129, 33, 128), (2, 20000, 4096), (257, 257, 257), (5, 5, 2)):
        blocks = reference_blocks(rows, cols, side)
        count = np.zeros((rows - 1, cols - 1), int)
        for b in blocks:
            assert b.shape[0] <= side and b.shape[1] <= side
            count[b.r0 : b.r1 - 1, b.c0 : b.c1 - 1] += 1
        assert (count == 1).all()


@pytest.mark.parametrize("shape", [(33, LIMIT + 1), (LIMIT + 1, 33)], ids=["wide", "tall"])
def test_every_method_draws_a_grid_past_the_texture_limit(ctx, small_limit, shape):
    hf = hills(*shape)
    view = along(hf)
    rng = np.random.default_rng(7)
    rows, cols = rng.integers(0, view.height, 240), rng.integers(0, view.width, 240)
    cpu = cpu_distances(hf, view, rows, cols)
    assert 0.15 < np.isfinite(cpu).mean() < 0.97  # the view shows terrain and sky
    results = {}
    for method in METHODS:
        opts = {} if method == "reference" else {"tau": 0.25} if method != "raycast" else {}
        with make_renderer(ctx, hf, method, tile_size=32) as r:
            results[method] = (
                r.render(view, mode="shaded", **opts) if method == "reference" else r.render(view, 0.25, mode="shaded")
            )
    ref = results["reference"]
    assert ref.stats.counters["blocks"] >= 1
    clear = ~near_silhouettes(ref.distance)[rows, cols]
    got = ref.distance[rows, cols].astype(np.float64)
    assert np.array_equal(np.isfinite(got)[clear], np.isfinite(cpu)[clear])
    both = clear & np.isfinite(cpu)
    assert np.abs(got[both] - cpu[both]).max() / cpu[both].min() < 1e-4
    for method, res in results.items():
        agree = float((res.mask == ref.mask).mean())
        assert agree >= 0.995, f"{method}: coverage agreement {agree:.4f} with the reference"
        d = res.distance[rows, cols].astype(np.float64)
        hit = clear & np.isfinite(cpu) & np.isfinite(d)
        assert np.median(np.abs(d[hit] - cpu[hit]) / cpu[hit]) < 2e-3, method


def test_the_reference_draws_in_blocks_the_same_image(ctx):
    hf = hills(65, 200)
    view = along(hf)
    with ReferenceRenderer(ctx, hf) as whole, ReferenceRenderer(ctx, hf, block_samples=17) as cut:
        a, b = whole.render(view, mode="shaded"), cut.render(view, mode="shaded")
        assert whole.drawn_blocks == 1 and cut.drawn_blocks > 20
    assert a.mask.mean() > 0.3
    assert np.array_equal(a.mask, b.mask)
    assert np.abs(a.distance[a.mask] - b.distance[a.mask]).max() <= 1e-5 * a.distance[a.mask].max()


def test_a_view_of_part_of_the_grid_draws_only_its_blocks(ctx):
    hf = hills(65, 513)
    ox, oy, oz = hf.origin
    view = View((ox + 100, oy + 900, oz + 400), (ox + 900, oy + 900, oz + 100), 50.0, 160, 96, far=3000.0)
    with ReferenceRenderer(ctx, hf, block_samples=33) as cut, ReferenceRenderer(ctx, hf) as whole:
        a, b = cut.render(view, mode="shaded"), whole.render(view, mode="shaded")
        assert 0 < cut.drawn_blocks < len(cut.blocks) // 2
    assert np.array_equal(a.mask, b.mask)


def test_a_stored_grid_streams_its_blocks_into_the_same_image(ctx, tmp_path, monkeypatch):
    from hybrid import reference
    from hybrid.terrain.grid_sources import HeightFieldSource
    from hybrid.terrain.stored import open_store
    from hybrid.tiles.store import prepare_store

    store = open_store(prepare_store(HeightFieldSource(hills(97, 161)), tmp_path / "hills", tile_size=32))
    hf = store.load()
    view = along(hf)
    monkeypatch.setattr(reference, "RESIDENT_SAMPLES", 0)
    with ReferenceRenderer(ctx, store, block_samples=33) as streamed, ReferenceRenderer(ctx, hf) as memory:
        assert not streamed.resident
        a, b = streamed.render(view, mode="shaded"), memory.render(view, mode="shaded")
        assert streamed.drawn_blocks > 4
    assert a.mask.mean() > 0.3
    assert np.array_equal(a.mask, b.mask)
    assert np.array_equal(a.distance, b.distance)


def test_a_streamed_grid_reads_only_the_blocks_its_host_cache_lacks(ctx, tmp_path, monkeypatch):
    from hybrid import reference
    from hybrid.terrain.grid_sources import HeightFieldSource
    from hybrid.terrain.stored import open_store
    from hybrid.tiles.store import prepare_store

    store = open_store(prepare_store(HeightFieldSource(hills(97, 161)), tmp_path / "hills", tile_size=32))
    view = along(store.load())
    monkeypatch.setattr(reference, "RESIDENT_SAMPLES", 0)
    with (
        ReferenceRenderer(ctx, store, block_samples=33) as all_held,
        ReferenceRenderer(ctx, store, block_samples=33, host_bytes=2 * 33 * 33 * 4) as two_held,
    ):
        first = all_held.render(view, mode="shaded")
        shown = all_held.drawn_blocks
        assert all_held.block_reads == shown > 4
        again = all_held.render(view, mode="shaded")
        assert all_held.block_reads == shown  # the second draw read nothing from disk
        assert np.array_equal(first.distance, again.distance)
        two_held.render(view, mode="shaded")
        two_held.render(view, mode="shaded")
        assert two_held.block_reads == 2 * shown - 2  # it held two blocks between the draws


def test_a_texture_past_the_limit_is_resampled_to_fit(ctx, small_limit):
    rng = np.random.default_rng(3)
    t = rng.integers(0, 256, (40, 300, 3), dtype=np.uint8)
    fitted = fit_texture(t, LIMIT)
    assert fitted.shape == (17, LIMIT, 3)
    assert abs(float(fitted.mean()) - float(t.mean())) < 2.0
    hf = hills(41, 301)
    hf.texture = np.full((40, 300, 3), (200, 40, 10), np.uint8)
    view = along(hf)
    with ReferenceRenderer(ctx, hf) as r:
        assert r.texture.size == (LIMIT, 17)
        res = r.render(view, mode="texture")
    colours = res.colour[res.mask].astype(int)
    assert res.mask.mean() > 0.1
    assert np.abs(colours - (200, 40, 10)).max() <= 2


@pytest.mark.parametrize("shape", [(2, 2000), (3000, 2), (8, 600)], ids=["2x2000", "3000x2", "8x600"])
def test_the_default_view_of_a_thin_strip_frames_it(ctx, shape):
    from hybrid.camera.view import default_view

    hf = hills(*shape, spacing=10.0)
    view = default_view(hf, 160, 90)
    with ReferenceRenderer(ctx, hf) as r:
        res = r.render(view, mode="shaded")
    assert res.mask.mean() > 0.08
    assert res.mask[-1].mean() > 0.3  # the strip runs from the bottom of the image


def test_the_default_view_of_a_square_terrain_is_unchanged():
    from hybrid.camera.view import default_view

    hf = hills(65, 65)
    v = default_view(hf, 160, 90)
    w, d = hf.extent
    assert np.allclose(v.eye[:2], (hf.origin[0] + 0.25 * w, hf.origin[1] - 0.08 * d))


def test_render_draws_a_tile_store_with_every_method(ctx, tmp_path):
    """``render --dataset STORE`` with each method at the store's own tile size, against its reference."""
    from experiments.cli import main
    from experiments.metrics import coverage_errors

    assert main(["prepare", "--synthetic", "129", "--tile-size", "32", "--out", str(tmp_path / "s"), "--quiet"]) == 0
    frames = {}
    for method in METHODS:
        out = tmp_path / f"{method}.png"
        assert (
            main(
                [
                    "render",
                    "--dataset",
                    str(tmp_path / "s"),
                    "--method",
                    method,
                    "--size",
                    "160x90",
                    "--shading",
                    "shaded",
                    "--out",
                    str(out),
                ]
            )
            == 0
        ), method
        frames[method] = np.load(tmp_path / f"{method}.depth.npy")

    class Frame:
        def __init__(self, d):
            self.distance, self.colour = d, np.zeros(d.shape + (3,), np.uint8)

    ref = Frame(frames["reference"])
    assert np.isfinite(ref.distance).mean() > 0.3
    for method, d in frames.items():
        cov = coverage_errors(Frame(d), ref)
        assert cov["crack_px"] == 0 and cov["coverage_mismatch"] < 0.005, (method, cov)


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from([-2, -1, 0, 1, 2, 31, 32, 33]), st.sampled_from([-1, 0, 1, 32]), st.booleans())
def test_grids_around_the_texture_limit_draw_as_one_texture_does(ctx, dc, dr, wide):
    """Grids a few samples either side of one and two limits: the reference with the limit forced to 32 draws
    the image it draws with the grid in one texture."""
    limit = 32
    cols, rows = limit + dc if dc < 31 else 2 * limit + dc - 32, 12 + dr
    hf = hills(*((rows, cols) if wide else (cols, rows)))
    view = along(hf, 96, 64)
    whole, cut = ReferenceRenderer(ctx, hf), None
    context_extra(ctx)["max_texture_size"] = limit
    try:
        cut = ReferenceRenderer(ctx, hf)
        assert all(max(b.shape) <= limit for b in cut.blocks) and len(cut.blocks) >= 1 + (max(hf.rows, hf.cols) > limit)
        a, b = whole.render(view, mode="shaded"), cut.render(view, mode="shaded")
    finally:
        context_extra(ctx).pop("max_texture_size", None)
        whole.release()
        if cut is not None:
            cut.release()
    assert np.array_equal(a.mask, b.mask)
    assert np.abs(a.distance[a.mask] - b.distance[a.mask]).max(initial=0) <= 1e-5 * a.distance[a.mask].max(initial=1)


def test_a_run_on_a_tile_store_measures_accuracy_against_its_reference(ctx, tmp_path):
    """A spec whose dataset is a tile store runs with accuracy on: the reference is drawn from the store."""
    import pandas as pd

    from experiments.cli import main

    assert main(["prepare", "--synthetic", "129", "--tile-size", "32", "--out", str(tmp_path / "st"), "--quiet"]) == 0
    spec = tmp_path / "s.toml"
    spec.write_text(
        f'name = "s"\ndatasets = ["{tmp_path / "st"}"]\nflights = ["flyover"]\nframes = 2\n'
        'policies = ["raycast", "raster"]\nsizes = ["96x64"]\nrepeats = 3\ntile_size = 32\n'
        "supersample = 1\nimage_frames = [0]\n"
    )
    assert main(["run", str(spec), "--runs", str(tmp_path / "runs"), "--quiet"]) == 0
    frames = pd.read_parquet(tmp_path / "runs" / "s" / "frames.parquet")
    assert len(frames) == 4
    assert (frames["crack_px"] == 0).all() and (frames["coverage_mismatch"] < 0.01).all()
    assert (frames["ref_coverage"] > 0.2).all()


def test_prepare_says_when_an_elongated_grid_pays_for_its_square(tmp_path, capsys):
    from experiments.cli import main
    from experiments.cli.prepare import square_note

    assert square_note(16385, 16385, 256) is None and square_note(1025, 513, 256) is None
    assert "6711x its samples" in square_note(8, 20000, 256)
    np.save(tmp_path / "strip.npy", hills(3, 257).heights)
    assert (
        main(
            [
                "prepare",
                str(tmp_path / "strip.npy"),
                "--spacing",
                "10",
                "--tile-size",
                "16",
                "--quiet",
                "--out",
                str(tmp_path / "s"),
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert "257x3 samples" in err and "86x its samples" in err
