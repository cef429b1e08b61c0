"""Shared checks of the edit and deformation tests: a renderer that followed changes of its terrain draws it as
renderers made afresh on the changed heights do."""

import dataclasses

import numpy as np

from experiments.metrics import crack_pixels
from experiments.spec import load_spec
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.terrain.heightfield import HeightField


def tiny_edit_spec(name: str, edit: dict, **changes):
    """The bundled edit spec at a tiny size (Puget at 129², tiles of 32, 3 frames of 96x54) named ``name``, its
    programme and its other fields changed as given."""
    spec = load_spec("edit", {"frames": 3, "sizes": ["96x54"]})
    return dataclasses.replace(
        spec, dataset_size=129, tile_size=32, name=name, edit=dataclasses.replace(spec.edit, **edit), **changes
    )


def copy_terrain(hf: HeightField) -> HeightField:
    """An in-memory terrain with its own copy of hf's heights (edits of one leave the other as it was)."""
    return HeightField(hf.heights.copy(), hf.spacing, hf.origin, hf.name, hf.texture, source_step=hf.source_step)


def assert_draws_as_fresh(ctx, r: Renderer, ref: ReferenceRenderer, views, before) -> None:
    """Each view drawn by ``r`` and ``ref`` (which followed the changes) equals what a renderer and a reference
    made afresh on a copy of the changed heights draw: distances within 1e-5, the same coverage, the reference
    bit for bit, and a mixed policy's tile plans and features; no crack against the followed reference; and
    the change is in view (somewhere the distance moved over 100 m from ``before``, the frames drawn before it)."""
    fresh_hf = copy_terrain(r.hf)
    tile_size = r.pyramid.n
    with (
        Renderer(
            ctx,
            fresh_hf,
            r.policy,
            tile_size=tile_size,
            adapt=False,
            cost_model=r.model,
            reuse_choice=1,
            strategy_options=r.options,  # the same tile formats and draw options
        ) as fresh,
        ReferenceRenderer(ctx, fresh_hf) as fresh_ref,
    ):
        for v, b in zip(views, before, strict=True):
            a, want = r.render(v), fresh.render(v)
            np.testing.assert_allclose(a.distance, want.distance, rtol=1e-5)
            assert np.array_equal(np.isfinite(a.distance), np.isfinite(want.distance))
            got_ref = ref.render(v)
            np.testing.assert_array_equal(got_ref.distance, fresh_ref.render(v).distance)
            assert int(crack_pixels(a, got_ref).sum()) == 0
            if r.mixed:  # per-tile features of the changed tiles
                got_plans, want_plans = r.plan(v), fresh.plan(v)
                assert [p.key for p in got_plans] == [p.key for p in want_plans]
                assert [p.features for p in got_plans] == [p.features for p in want_plans]
            moved = np.isfinite(a.distance) & np.isfinite(b.distance)
            assert np.abs(a.distance[moved] - b.distance[moved]).max() > 100.0  # the change is in view
