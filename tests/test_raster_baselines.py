"""Baselines: the full-resolution triangle list matches the reference; the TIN is decimated, exports, and
its border cracks are measured; the indexed list of a tilelet set matches the GS count."""
import numpy as np
import pytest

from hybrid.camera.view import default_view
from hybrid.errors import TerrabenchError
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from raster.tin import border_gaps, build_tin, export_tin, tin_max_error


def test_fullres_matches_reference(ctx, puget257):
    view = default_view(puget257, 320, 180)
    r = Renderer(ctx, puget257, "fullres", tile_size=64)
    try:
        res = r.render(view, mode="shaded")
        ref = ReferenceRenderer(ctx, puget257).render(view, mode="shaded")
        assert np.array_equal(res.mask, ref.mask)
        assert np.abs(res.colour.astype(int) - ref.colour).max() <= 2
        assert res.stats.counters["triangles"] == res.stats.counters["triangles_cpu"] == 2 * 256 * 256
    finally:
        r.release()


def test_tin_decimates_exports_and_cracks_are_measured(ctx, puget257, tmp_path):
    view = default_view(puget257, 320, 180)
    r = Renderer(ctx, puget257, "tin", tile_size=64)
    try:
        res = r.render(view, mode="shaded")
        assert res.stats.counters["triangles"] == res.stats.counters["triangles_cpu"] < 0.15 * 2 * 256 * 256
        gaps = border_gaps(r.strategies["tin"].meshes, 64)
        assert len(gaps) == 24 and max(gaps.values()) > 1.0      # independent decimation cracks: measured, not hidden
        mesh, sp = next(iter(r.strategies["tin"].meshes.values()))
        export_tin(mesh, tmp_path / "tile.obj")
        export_tin(mesh, tmp_path / "tile.ply")
        assert (tmp_path / "tile.obj").stat().st_size > 0 and (tmp_path / "tile.ply").stat().st_size > 0
        with pytest.raises(TerrabenchError, match="obj or .ply"):
            export_tin(mesh, tmp_path / "tile.stl")
    finally:
        r.release()
    h = puget257.heights[:65, :65]
    sp = (puget257.spacing_x, puget257.spacing_y)
    m = build_tin(h, sp, max_error=40.0, preserve_border=True)
    err, uncovered = tin_max_error(m, h, sp)
    assert err <= 40.0 and uncovered == 0 and m.triangles < 2 * 64 * 64
    with pytest.raises(TerrabenchError, match="exactly one"):
        build_tin(h, 1.0)
