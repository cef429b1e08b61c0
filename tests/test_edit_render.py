"""Every strategy draws the edited terrain as a renderer made afresh on it would, and without cracks."""

import numpy as np
import pytest

from experiments.metrics import crack_pixels
from hybrid.camera.flight import preset
from hybrid.editing import TerrainEditor
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.terrain.datasets import puget
from hybrid.terrain.edits import Crater, Raise
from hybrid.terrain.heightfield import HeightField

SIZE = (320, 180)


def _copy(hf):
    return HeightField(hf.heights.copy(), hf.spacing, hf.origin, hf.name, hf.texture, source_step=hf.source_step)


@pytest.mark.parametrize("policy", ["raster", "raster_gs", "raycast", "hybrid"])
def test_strategies_follow_edits_across_tile_borders(ctx, policy):
    hf = _copy(puget(size=257))
    ox, oy, _ = hf.origin
    edits = [
        Crater((ox + 20480.0, oy + 20480.0), 6000.0, 900.0),  # a corner of four 64-cell tiles
        Raise((ox + 10240.0, oy + 30000.0), 3000.0, 600.0),
    ]  # on a tile border
    fly = preset("flyover", hf, 6, *SIZE)
    views = [fly.view(1), fly.view(3)]
    r = Renderer(ctx, hf, policy, tile_size=64, adapt=False)
    ref = ReferenceRenderer(ctx, hf)
    editor = TerrainEditor(ctx, hf, r, ref)
    try:
        before = [r.render(v) for v in views]  # tiles resident before the edit
        reports = [editor.apply(b) for b in edits]
        after = [r.render(v) for v in views]
        assert any(rep.refreshed.get(n, 0) for rep in reports for n in r.strategies)
        fresh_hf = _copy(hf)
        with (
            Renderer(ctx, fresh_hf, policy, tile_size=64, adapt=False, cost_model=r.model) as fresh,
            ReferenceRenderer(ctx, fresh_hf) as fresh_ref,
        ):
            for v, a, b in zip(views, after, before, strict=True):
                want = fresh.render(v)
                np.testing.assert_allclose(a.distance, want.distance, rtol=1e-5)
                assert np.array_equal(np.isfinite(a.distance), np.isfinite(want.distance))
                got_ref, want_ref = ref.render(v), fresh_ref.render(v)
                np.testing.assert_array_equal(got_ref.distance, want_ref.distance)
                assert int(crack_pixels(a, got_ref).sum()) == 0
                if policy == "hybrid":  # per-tile features of the edited tiles
                    got_plans, want_plans = r.plan(v), fresh.plan(v)
                    assert [p.key for p in got_plans] == [p.key for p in want_plans]
                    assert [p.features for p in got_plans] == [p.features for p in want_plans]
                moved = np.isfinite(a.distance) & np.isfinite(b.distance)
                assert np.abs(a.distance[moved] - b.distance[moved]).max() > 100.0  # the edit is in view
    finally:
        for x in (editor, ref, r):
            x.release()
