"""The raster benchmark's memory table: every representation's resident bytes per tile, and a drawn leaf's
arena bytes as the reports give them (an "exact"-rule leaf: 9 vec4 vertices and 24 indices, or a 13-word record)."""

from experiments.bench_raster import memory_rows
from hybrid.tiles.pyramid import TilePyramid


def test_memory_rows_name_every_representation_and_the_arena_leaf_bytes(ctx, puget257):
    pyr = TilePyramid(puget257, 64)
    rows = memory_rows(ctx, puget257, [pyr.tile(pyr.keys(0)[0])])
    by_name = {r[0]: r for r in rows}
    assert by_name["raster arena, a drawn leaf"][1] == 9 * 16 + 24 * 4
    assert by_name["raster_gs arena, a drawn leaf"][1] == 13 * 4
    for name in ("tilelets resident (raster, raster_gs)", "fullres list", "tin 90% reduced"):
        assert by_name[name][1] > 0 and by_name[name][2] > 0
    assert by_name["paper: list indices"][2] == 2 * 64 * 64
