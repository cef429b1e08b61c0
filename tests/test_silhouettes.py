"""Where the ray caster and the reference disagree near full resolution, an exact intersection sides with one."""

import pytest

from experiments.silhouettes import disagreements
from hybrid.camera.flight import preset
from hybrid.camera.view import default_view


@pytest.mark.gl
def test_near_full_resolution_the_ray_caster_matches_the_exact_hit_where_it_and_the_reference_differ(ctx, puget257):
    views = [default_view(puget257, 320, 180), preset("orbit", puget257, 4, 320, 180).view(0)]
    rows = [d for v in views for d in disagreements(ctx, puget257, v, taus=(0.05,), tile_size=64)]
    assert all(d["both"] > 20000 and d["median rel"] < 1e-6 for d in rows)
    assert sum(d["disagree"] for d in rows) > 0  # silhouettes where the two differ exist
    assert all(d["neither"] == 0 for d in rows)  # and the exact hit takes a side at each
    assert all(d["raycast right"] == d["disagree"] for d in rows)  # the ray caster's, on this terrain
