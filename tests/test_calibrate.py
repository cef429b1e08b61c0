"""Calibration on a tiny terrain and the renderer's per-tile timing: shapes, signs and counters, never speed."""

import numpy as np
import pytest

from hybrid.calibrate import calibrate
from hybrid.camera.flight import preset
from hybrid.contract import DEFAULT_FULL_RES, TileItem
from hybrid.cost.model import TERMS
from hybrid.gl.context import gl_info
from hybrid.gl.target import FrameTarget
from hybrid.renderer import Renderer
from hybrid.strategies import candidates
from hybrid.terrain.datasets import get_dataset

TILE = 32


@pytest.fixture(scope="module")
def fbm129():
    return get_dataset("fbm", size=129)


@pytest.fixture(scope="module")
def views(fbm129):
    fly = preset("flyover", fbm129, 4, 160, 90)
    return [fly.view(1), fly.view(2)]


def test_calibrate_fits_the_tiles_the_renderer_selects(ctx, fbm129, views):
    cal = calibrate(ctx, fbm129, views, tile_size=TILE, repeats=1, holdout=0.3, seed=0)
    with Renderer(ctx, fbm129, "hybrid", TILE) as r:
        plans = [r.plan(v) for v in views]
    assert cal.features == [p.features for frame in plans for p in frame]
    n = len(cal.features)
    assert n >= 8
    assert set(cal.times) == set(candidates())
    for ms in cal.times.values():
        assert ms.shape == (n,) and np.all(np.isfinite(ms)) and np.all(ms > 0)
    assert len(cal.frames) == len(views)
    for rec, frame in zip(cal.frames, plans):
        for name in candidates():
            in_frame, together = rec[name]
            assert len(in_frame) == len(frame) and together > 0
    per_view = len(candidates()) + 6  # each candidate alone, then six random assignments
    assert len(cal.samples) == len(views) * per_view
    for i, (sample, frame) in enumerate(zip(cal.samples, [p for p in plans for _ in range(per_view)])):
        assert sample.ms > 0 and np.isfinite(sample.ms)
        if i % per_view < len(candidates()):  # a pure frame: its strategy holds every tile's terms
            name = candidates()[i % per_view]
            assert [k for k, u in sample.used.items() if u] == [name]
            assert np.isclose(sample.sums[name][0], len(frame))  # the const term counts tiles
        else:
            assert sum(sample.used.values()) >= 2 or len(frame) < 2
            assert np.isclose(sum(sample.sums[k][0] for k in candidates()), len(frame))
    m = cal.model
    assert m.tiles == n and m.frames == len(cal.samples) and m.renderer == gl_info(ctx).renderer
    assert m.full_res == DEFAULT_FULL_RES  # the rule its raster frames were drawn by
    for s in candidates():
        coef = m.coefficients[s]
        assert set(coef) == set(TERMS[s])
        assert all(np.isfinite(c) and c >= 0 for c in coef.values()), (s, coef)
        assert np.isfinite(m.overhead[s]) and m.overhead[s] >= 0
        assert np.isfinite(m.fit_error[s]) and m.fit_error[s] >= 0
        assert np.isfinite(m.tile_error[s]) and m.tile_error[s] >= 0
    for f in cal.features:  # a fitted model predicts a finite, non-negative cost
        assert all(np.isfinite(c) and c >= 0 for c in m.predict(f).values())


@pytest.mark.parametrize("name", candidates())
def test_time_draw_positive_and_counters_grow_with_tiles(ctx, fbm129, views, name):
    v = views[1]
    with Renderer(ctx, fbm129, name, TILE, oracle_repeats=2) as r:
        plans = r.plan(v)
        assert len(plans) >= 4
        target = FrameTarget(ctx, v.width, v.height)
        try:
            counters = []
            for k in (1, len(plans) // 2, len(plans)):
                assert r.time_draw(v, plans[:k], name, target) > 0
                items = [
                    TileItem(
                        r.cache.get(name, r.strategies[name], p.key, lambda p=p: r.tile(p.key)),
                        r.tile(p.key),
                        p.selected,
                    )
                    for p in plans[:k]
                ]
                target.clear()
                target.use()
                counters.append(r.strategies[name].draw_tiles(target, v, items, 2 / 3, **r.options[name].values()))
        finally:
            target.release()
    work = "rays" if name == "raycast" else "triangles"
    counts = [c[work] for c in counters]
    assert counts[0] > 0 and counts == sorted(counts), counts  # front-to-back prefixes: never less work
