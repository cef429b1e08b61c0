"""The choice benchmark at its smallest: the hybrid forced to one strategy draws its frames that way, beside the
pure method drawn twice, and the table carries the target's ratio and its noise floor."""

import numpy as np

from experiments.bench_choice import AGAIN, EVERY, FLOOR, TARGET, draw, run
from hybrid.camera.flight import preset
from hybrid.cost.model import shipped_cost_model
from hybrid.gl.context import gl_info


def test_the_pure_method_is_drawn_twice_beside_the_forced_hybrid(ctx, puget257):
    views = preset("orbit", puget257, 3, 160, 90).views()
    model = shipped_cost_model(gl_info(ctx).renderer)
    df = draw(ctx, puget257, views, 2 / 3, 64, model, "raster", repeats=2)
    assert set(df.policy) == {"raster", AGAIN, "hybrid", EVERY}
    tiles = df.pivot(index="frame", columns="policy", values="tiles")
    assert (tiles["raster"] > 0).all()
    for p in (AGAIN, "hybrid", EVERY):  # the same tiles every way
        assert (tiles[p] == tiles["raster"]).all(), p
    assert all(len(w) == 2 for w in df.wall_ms_repeats) and (df.wall_ms > 0).all()


def test_the_table_gives_the_target_and_its_floor(ctx):
    tables = run(ctx, frames=2, size="160x90", repeats=1, flights=("orbit",), methods=("raster",), tile_sizes=(64,))
    (table,) = tables.values()
    assert len(table) == 1
    row = table.iloc[0]
    assert np.isfinite(row[TARGET]) and row[TARGET] > 0
    assert np.isfinite(row[FLOOR]) and row[FLOOR] > 0
