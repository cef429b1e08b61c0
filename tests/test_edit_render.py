"""Every strategy draws the edited terrain as a renderer made afresh on it would, and without cracks."""

import pytest
from edit_helpers import assert_draws_as_fresh, copy_terrain

from hybrid.camera.flight import preset
from hybrid.editing import TerrainEditor
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.terrain.datasets import puget
from hybrid.terrain.edits import Crater, Raise

SIZE = (320, 180)


@pytest.mark.parametrize(
    ("policy", "options"),
    [("raster", {}), ("raster_gs", {}), ("raycast", {}), ("raycast", {"heights": "float32"}), ("hybrid", {})],
)
def test_strategies_follow_edits_across_tile_borders(ctx, policy, options):
    hf = copy_terrain(puget(size=257))
    ox, oy, _ = hf.origin
    edits = [
        Crater((ox + 20480.0, oy + 20480.0), 6000.0, 900.0),  # a corner of four 64-cell tiles
        Raise((ox + 10240.0, oy + 30000.0), 3000.0, 600.0),
    ]  # on a tile border
    fly = preset("flyover", hf, 6, *SIZE)
    views = [fly.view(1), fly.view(3)]
    # every frame planned: features compared
    r = Renderer(ctx, hf, policy, tile_size=64, adapt=False, reuse_choice=1, **options)
    ref = ReferenceRenderer(ctx, hf)
    editor = TerrainEditor(ctx, hf, r, ref)
    try:
        before = [r.render(v) for v in views]  # tiles resident before the edit
        reports = [editor.apply(b) for b in edits]
        assert any(rep.refreshed.get(n, 0) for rep in reports for n in r.strategies)
        assert_draws_as_fresh(ctx, r, ref, views, before)
    finally:
        for x in (editor, ref, r):
            x.release()
