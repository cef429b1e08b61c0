"""Skirts of the unstitched baselines (raster.mesh_skirts): where a T-junction between tile levels lets the sky
through, the full-resolution list without skirts shows crack pixels and with them none, the filled pixels lie on
a seam between levels, and nothing else changes; the decimated TIN's seams close as well; views from under the
sheet gain no walls; a TIN's strayed border is covered by the flange."""

import numpy as np
import pytest
from test_phantom_walls import canyon
from test_phantom_walls import views as canyon_views

from experiments.metrics import coverage_errors
from hybrid.camera.view import View, default_view
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.terrain.datasets import ridged
from raster.mesh_skirts import grid_border_edges, mesh_border_edges, seam_gap, side_skirt
from raster.tin import build_tin, surface_at, tin_max_error

TILE = 16
SIZE = (320, 180)
TAU = 3.0  # px: coarse enough that level-1 tiles meet level-0 ones in the view
# grazing views across the rough terrain (metres from its origin): from over its east edge and from west of it
# (that one also sends rays in under the outer edge)
VIEWS = {
    "east": ((7821.7, 4414.9, 2192.5), (3406.9, 6026.4, 605.2)),
    "west": ((-1581.7, 1250.0, 1723.2), (2372.4, 4937.4, 180.2)),
}


def rough():
    """Ridged 257² terrain 2 km high at 30 m: steep enough that a level-1 tile edge leaves its level-0 neighbour's
    samples metres above or below it."""
    return ridged(257, 30.0, 0, amplitude=2000.0)


def frames(ctx, hf, view, method, tile, tau, **kw):
    """(reference, frame without skirts, frame with skirts, the skirted frame's plans)."""
    with ReferenceRenderer(ctx, hf) as ref, Renderer(ctx, hf, method, tile_size=tile, **kw) as r:
        want = ref.render(view, mode="shaded")
        bare = r.render(view, tau=tau, mode="shaded", seam_skirts=False)
        skirted = r.render(view, tau=tau, mode="shaded")
    return want, bare, skirted


def level_seams(plans, n: int) -> list:
    """Sides between selected tiles of different levels as level-0 segments ((x0, y0), (x1, y1)) in cells."""
    out = []
    for p in plans:
        span = n << p.key.level
        x0, y0 = p.key.tx * span, p.key.ty * span
        ends = (
            ((x0, y0), (x0, y0 + span)),
            ((x0 + span, y0), (x0 + span, y0 + span)),
            ((x0, y0), (x0 + span, y0)),
            ((x0, y0 + span), (x0 + span, y0 + span)),
        )
        out += [ends[k] for k, d in enumerate(p.selected.edge_deltas) if d in (-1, 1)]
    return out


def cells_to_seams(points: np.ndarray, seams: list) -> np.ndarray:
    """Distance (level-0 cells) from each point (P, 2) to the nearest of the segments."""
    a = np.array([s[0] for s in seams], dtype=np.float64)
    b = np.array([s[1] for s in seams], dtype=np.float64)
    ab = b - a
    t = np.clip(((points[:, None] - a) * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
    return np.linalg.norm(points[:, None] - (a + t[..., None] * ab), axis=-1).min(axis=1)


@pytest.mark.parametrize("name", sorted(VIEWS))
def test_skirts_close_the_full_resolution_baselines_t_junctions(ctx, name):
    hf = rough()
    o = np.asarray(hf.origin)
    eye, target = VIEWS[name]
    view = View(o + eye, o + target, 60.0, *SIZE, near=1.0, far=10 * hf.extent[0])
    want, bare, skirted = frames(ctx, hf, view, "fullres", TILE, TAU)
    seams = level_seams(skirted.plans, TILE)
    assert seams, "the view selects no neighbours of different levels"
    before, after = coverage_errors(bare, want), coverage_errors(skirted, want)
    assert before["crack_px"] >= 4 and after["crack_px"] == 0, (before["crack_px"], after["crack_px"])
    assert 1 - after["coverage_mismatch"] >= 0.999, after
    c = skirted.stats.counters
    assert c["skirt_triangles"] > 0 and c["triangles"] == bare.stats.counters["triangles"]
    # the pixels that changed: sky, or a surface behind, seen through the seam before; now the skirt, nearer the
    # reference's distance, on a seam between levels
    d0, d1, dr = bare.distance, skirted.distance, want.distance
    changed = (d0 != d1) | (bare.colour != skirted.colour).any(axis=2)
    assert changed.sum() >= before["crack_px"]
    d0, d1, dr = d0[changed], d1[changed], dr[changed]
    assert np.isfinite(dr).all() and (d1 < d0).all() and (np.abs(d1 - dr) < np.abs(d0 - dr)).all()
    ys, xs = np.nonzero(changed)
    hit = view.eye + view.pixel_rays(ys, xs) * d1[:, None]
    cells = (hit[:, :2] - o[:2]) / np.array([hf.spacing_x, hf.spacing_y])
    assert cells_to_seams(cells, seams).max() < 0.05


def test_skirt_depth_is_the_largest_step_of_a_t_junction(ctx):
    """A side between levels hangs as deep as the coarser surface leaves the finer one's samples (level l+1 keeps
    every other level-l sample, so the step is an odd sample against its neighbours' mean), plus 1 % of the sample
    spacing; a same-level side of the grid none."""
    from hybrid.contract import TileItem
    from hybrid.strategies import make_strategy
    from hybrid.tiles.pyramid import TilePyramid
    from hybrid.tiles.tiletree import select_tiles

    hf = rough()
    o = np.asarray(hf.origin)
    eye, target = VIEWS["east"]
    view = View(o + eye, o + target, 60.0, *SIZE, near=1.0, far=10 * hf.extent[0])
    pyramid = TilePyramid(hf, TILE)
    s = make_strategy("fullres", ctx, hf)
    sel = select_tiles(pyramid, view, TAU)
    items = [TileItem(s.upload(pyramid.tile(t.key)), pyramid.tile(t.key), t) for t in sel]
    try:
        depths = s.depths(items)
    finally:
        for it in items:
            it.gpu.release()
        s.release()
    steps = {}  # (fine key, side) -> the largest step along it
    for it in items:
        h = np.asarray(it.tile.heights, dtype=np.float64)
        for k, e in enumerate((h[:, 0], h[:, -1], h[0], h[-1])):
            steps[it.selected.key, k] = np.abs(e[1:-1:2] - 0.5 * (e[:-2:2] + e[2::2])).max()
    checked = {1: 0, -1: 0}
    for it, dep in zip(items, depths):
        key, sp = it.selected.key, max(it.tile.spacing_x, it.tile.spacing_y)
        for k, (dx, dy) in enumerate(((-1, 0), (1, 0), (0, -1), (0, 1))):
            delta = it.selected.edge_deltas[k]
            if delta == 1:  # this tile is the finer: its own samples make the step
                want = steps[key, k]
            elif delta == -1:  # the two finer tiles across make it
                fine = [
                    f
                    for f in (t.selected.key for t in items)
                    if f.level == key.level - 1
                    and (f.tx >> 1, f.ty >> 1) == (key.tx + dx, key.ty + dy)
                    and (f.tx & 1 == (dx < 0) if dx else f.ty & 1 == (dy < 0))
                ]
                want = max(steps[f, k ^ 1] for f in fine)
            elif delta == 0:
                assert dep[k] == 0
                continue
            else:
                continue
            assert dep[k] == pytest.approx(want + 0.01 * sp, rel=1e-9, abs=1e-9), (key, k)
            checked[delta] += 1
    assert min(checked.values()) >= 2, checked


def test_skirts_close_the_tins_seams(ctx, puget257):
    """Decimated apart, neighbouring TINs part along their shared sides at every level: crack pixels without
    skirts, none with them, and the coverage agreement rises (to 99.9 % or more)."""
    from hybrid.camera.flight import preset

    views = [default_view(puget257, *SIZE)] + preset("orbit", puget257, 6, *SIZE).views()[:3]
    for view in views:
        want, bare, skirted = frames(ctx, puget257, view, "tin", 64, 2 / 3)
        before, after = coverage_errors(bare, want), coverage_errors(skirted, want)
        assert before["crack_px"] >= 3 and after["crack_px"] == 0, (before["crack_px"], after["crack_px"])
        assert after["hole_px"] < before["hole_px"] and after["coverage_mismatch"] < before["coverage_mismatch"]
        assert 1 - after["coverage_mismatch"] >= 0.999, after
        assert skirted.stats.counters["triangles"] == bare.stats.counters["triangles"]


@pytest.mark.parametrize("method", ["fullres", "tin"])
def test_views_from_under_the_sheet_gain_no_walls(ctx, method):
    """From under the sheet (an eye below the ground, or outside below the outer edge) the skirts rise instead of
    hanging: the seams' crack pixels close, and for the full-resolution list nothing but formerly open pixels
    changes (sky, or a surface behind the seam), each now nearer the reference's distance."""
    hf = canyon()
    views = canyon_views(hf)
    opened = 0
    for name in ("outside_floor", "outside_wall", "below"):
        want, bare, skirted = frames(ctx, hf, views[name], method, TILE, 2 / 3)
        before, after = coverage_errors(bare, want), coverage_errors(skirted, want)
        opened += before["crack_px"]
        assert after["crack_px"] == 0, (name, after)
        assert after["coverage_mismatch"] <= before["coverage_mismatch"], name
        if method == "fullres":
            d0, d1, dr = bare.distance, skirted.distance, want.distance
            changed = (d0 != d1) | (bare.colour != skirted.colour).any(axis=2)
            d0, d1, dr = d0[changed], d1[changed], dr[changed]
            assert np.isfinite(dr).all() and (d1 < d0).all() and (np.abs(d1 - dr) < np.abs(d0 - dr)).all(), name
    assert opened >= 3


def test_rays_may_start_under_whenever_a_pixel_does():
    """The under pass is drawn whenever some pixel's ray starts under the sheet (hybrid.terrain.edges), and not for
    an eye above the ground over the footprint nor for views that keep above the outer edges."""
    from hybrid.terrain.datasets import puget
    from hybrid.terrain.edges import edge_profiles, starts_under
    from raster.mesh_skirts import rays_may_start_under

    hf = canyon()
    tops = edge_profiles(hf.heights).max(axis=1)
    views = list(canyon_views(hf).values())
    ox, oy, oz = hf.origin
    w, d = hf.extent
    far_above = View([ox - 0.5 * w, oy + 0.5 * d, oz + 5000.0], [ox + 0.5 * w, oy + 0.5 * d, oz + 4000.0], 40.0, *SIZE)
    views.append(far_above)  # outside, looking over the terrain: no ray under its edge
    said = []
    for v in views:
        under = starts_under(hf, v.eye, v.pixel_rays().reshape(-1, 3)).any()
        said.append(rays_may_start_under(hf, v, tops))
        assert said[-1] or not under
    assert said == [True, True, True, False, False]
    p = puget()
    assert rays_may_start_under(p, default_view(p, *SIZE), edge_profiles(p.heights).max(axis=1))


def test_a_strayed_tin_border_is_covered_by_the_flange():
    """A TIN whose border strays inside its square leaves samples uncovered; with each side's flange every sample is
    covered, and each side's skirt line runs from corner to corner on the side."""
    hf = rough()
    n = TILE
    h = hf.heights[: n + 1, : n + 1]
    sp = (hf.spacing_x, hf.spacing_y)
    m = build_tin(h, sp, target_count=int(0.1 * 2 * n * n))
    assert tin_max_error(m, h, sp)[1] > 0  # the border strayed: samples left uncovered
    extent = (n * sp[0], n * sp[1])
    tris = [m.vertices[m.faces]]
    for k, edges in enumerate(mesh_border_edges(m.vertices, m.faces, extent)):
        line, flange = side_skirt(m.vertices, edges, k, extent)
        a = 1 if k < 2 else 0
        assert np.all(line[:, 1 - a] == (0.0 if k % 2 == 0 else extent[1 - a]))
        assert line[0, a] == 0.0 and line[-1, a] == extent[a] and np.all(np.diff(line[:, a]) >= 0)
        tris.append(flange)
    soup = np.concatenate(tris)
    i, j = np.mgrid[0 : n + 1, 0 : n + 1]
    _, hits = surface_at(
        soup.reshape(-1, 3), np.arange(3 * len(soup)).reshape(-1, 3), j.ravel() * sp[0], i.ravel() * sp[1]
    )
    assert (hits > 0).all()
    # a grid's border is on its sides already: its skirt line is its border samples, bit for bit, and no flange
    rows, cols = 5, 7
    v = np.stack(
        [np.tile(np.arange(cols) * 2.0, rows), np.repeat(np.arange(rows) * 3.0, cols), np.arange(rows * cols) * 0.1], 1
    ).astype(np.float32)
    for k, edges in enumerate(grid_border_edges(rows, cols)):
        line, flange = side_skirt(v, edges, k, (12.0, 12.0))
        assert len(flange) == 0 and np.array_equal(line.astype(np.float32), v[np.unique(edges)])


def test_seam_gap_is_the_largest_distance_between_two_profiles():
    """Two piecewise-linear side profiles: the gap is taken at every vertex of either, within the shared stretch."""
    fine = (np.array([0.0, 1.0, 2.0, 3.0, 4.0]), np.array([0.0, 5.0, 0.0, -3.0, 0.0]))  # a level's samples
    coarse = (np.array([0.0, 2.0, 4.0]), np.array([0.0, 0.0, 0.0]))  # every other one
    assert seam_gap(fine, coarse, 0.0, 4.0) == 5.0
    assert seam_gap(fine, coarse, 2.0, 4.0) == 3.0
    assert seam_gap(coarse, coarse, 0.0, 4.0) == 0.0
