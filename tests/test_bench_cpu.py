"""The CPU benchmark: frames drawn by a child process on Mesa's no-op driver, every policy and default flight timed."""

import numpy as np
import pytest

from experiments.bench_cpu import FLIGHTS, POLICIES, READ_BACK, TARGET, run_child, summarize
from hybrid.gl.context import gl_info, is_software


@pytest.mark.slow
def test_child_draws_every_policy_on_the_no_op_driver(ctx):
    if not is_software(ctx):
        pytest.skip("the no-op driver is Mesa's; a GPU's driver draws for real")
    result = run_child(gl_info(ctx).renderer, frames=2, size="160x90", repeats=1)
    assert result["renderer"] == "NOOP"  # the child's GL did no drawing
    rows = result["rows"]
    ways = ("back", "read")
    assert {(r["way"], r["flight"], r["policy"]) for r in rows} == {
        (w, f, p) for w in ways for f in FLIGHTS for p in POLICIES
    }
    assert len(rows) == 2 * 2 * len(FLIGHTS) * len(POLICIES)
    for r in rows:
        assert np.isfinite([r["plan_ms"], r["issue_ms"], r["wall_ms"]]).all() and r["plan_ms"] > 0
        assert r["issue_ms"] > 0 and r["wall_ms"] >= r["plan_ms"]
    plan = {(r["flight"], r["policy"], r["frame"]): r["plan_ms"] for r in rows if r["way"] == "back"}
    # the hybrid selects the same tiles as raster and then estimates, measures and chooses: more planning
    assert np.median([plan[f, "hybrid", k] / plan[f, "raster", k] for f in FLIGHTS for k in range(2)]) > 1.2
    ((title, table),) = summarize(result).items()
    assert "no-op driver" in title and len(table) == len(FLIGHTS) * len(POLICIES)
    assert (table[TARGET] > table["plan ms"]).all() and (table[TARGET] > table["issue ms"]).all()
    assert (table[READ_BACK] > 0).all()
