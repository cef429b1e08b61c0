"""The edit benchmark at its smallest: a tiled terrain equal to Puget, real edits timed, bad arguments refused."""

import numpy as np
import pytest

from experiments.bench_edit import main, run, tiled_puget
from hybrid.terrain.datasets import puget


def test_tiled_puget_repeats_its_cells():
    base, big = puget(with_texture=False), tiled_puget(2049)
    assert big.heights.shape == (2049, 2049) and big.source_step == base.source_step
    np.testing.assert_array_equal(big.heights[:1024, 1024:2048], base.heights[:1024, :1024])
    np.testing.assert_array_equal(tiled_puget(1025).heights[:-1, :-1], base.heights[:-1, :-1])


def test_edit_bench_times_every_step_of_real_edits(ctx):
    (df,) = run(ctx, sizes=(1025,), methods=("raycast",), edits=3).values()
    row = df.iloc[0]
    steps = ("brush ms", "pyramid ms", "raycast ms", "update ms", "first edit ms", "frame ms", "back to back ms")
    for step in (*steps, "after a pause ms"):
        assert row[step] > 0, step
    assert row["refreshed tiles"] >= 1 and row["update / smallest (target <= 1.3)"] == 1.0
    assert row["update ms"] >= row["raycast ms"] + row["pyramid ms"]


@pytest.mark.parametrize("args", [["--sizes", "1000"], ["--sizes", "32769"], ["--methods", "tin"], ["--edits", "2"]])
def test_edit_bench_refuses_bad_arguments(args, capsys):
    with pytest.raises(SystemExit) as e:
        main(args)
    assert e.value.code == 2 and "--" in capsys.readouterr().err
