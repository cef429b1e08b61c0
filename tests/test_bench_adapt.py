"""The adaptation benchmark at its smallest: every repeat a cold adapting run, tables with the targets' columns."""

import copy

import numpy as np

from experiments.bench_adapt import FLOOR, SETTLED_FROM, TARGET, draw_flight, run, start_models
from hybrid.camera.flight import preset
from hybrid.cost.model import load_cost_model, save_cost_model, shipped_cost_model
from hybrid.gl.context import gl_info


def test_each_repeat_starts_the_adapting_hybrid_cold(ctx, puget257):
    """Every method draws every view once a repeat, the adapting hybrid a fresh one each repeat."""
    views = preset("orbit", puget257, 3, 160, 90).views()
    models = {"skewed": start_models(gl_info(ctx).renderer)["skewed"]}
    df = draw_flight(ctx, puget257, views, 2.0, models, repeats=2, tile_size=64)
    pure = {"raster", "raster_gs", "raycast"}
    assert set(df.method) == pure | {f"{p} (again)" for p in pure} | {"frozen:skewed", "hybrid:skewed"}
    assert all(len(w) == 2 for w in df.wall_ms_repeats) and (df.wall_ms > 0).all()
    assert len(df) == 8 * len(views)


def test_the_device_start_is_the_shipped_model_not_the_users_file(ctx, tmp_path, monkeypatch):
    renderer = gl_info(ctx).renderer
    want = shipped_cost_model(renderer)
    users = copy.deepcopy(want)
    users.renderer, users.overhead = renderer, {k: v + 7.0 for k, v in want.overhead.items()}
    path = tmp_path / "costs.json"
    save_cost_model(users, path)
    monkeypatch.setenv("TERRABENCH_COSTS", str(path))
    assert load_cost_model(renderer).overhead == users.overhead  # a user's run would start from the file
    got = start_models(renderer)
    assert got["device"].coefficients == want.coefficients and got["device"].overhead == want.overhead
    ray = want.coefficients["raycast"]
    assert np.allclose([got["skewed"].coefficients["raycast"][k] * 5 for k in ray], list(ray.values()))


def test_the_benchmark_reports_its_target_per_start(ctx):
    tables = run(
        ctx, frames=10, size="160x90", repeats=1, taus=(2.0,), flights=("orbit",), tile_size=64, starts=("skewed",)
    )
    (conv,) = [t for t in tables.values() if TARGET in t.columns]
    assert set(conv.start) == {"skewed", "device"} and (conv[TARGET] > 0).all()
    (frames,) = [t for t in tables.values() if "frame" in t.columns]
    late = frames[frames.frame >= SETTLED_FROM]  # one repeat: each frame's own ms
    best = conv["better pure"].iloc[0]
    floor = late[f"{best} (again)"].median() / late[best].median()
    assert np.allclose(conv[FLOOR], floor) and np.isfinite(floor) and floor > 0
