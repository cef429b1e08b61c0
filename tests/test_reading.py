"""The report's reading on constructed frame tables: a tie within noise is called a tie and never ranked, a clear
difference with small spread is called a difference, identical per-tile choices are named."""

import numpy as np
import pandas as pd

from experiments.noise import compare, repeat_matrix, repeat_spread
from experiments.reading import reading


def rows(policy, ms, spread, frames=8, seed=0, tiles_raster=0, tiles_raycast=10, tau=2.0, tiles_gs=0):
    """Frame rows of one method: each frame's repeats spread +-spread/2 around ms (times a per-frame wobble)."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(frames):
        centre = ms * (1 + 0.02 * np.sin(k))  # frames differ a little, as along a flight
        reps = list(centre * (1 + spread * (rng.random(3) - 0.5)))
        out.append(
            {
                "dataset": "fbm",
                "flight": "flyover",
                "size": "160x90",
                "tau": tau,
                "reconstruction": "triangles",
                "policy": policy,
                "frame": k,
                "wall_ms": float(np.median(reps)),
                "wall_ms_repeats": reps,
                "tiles": tiles_raster + tiles_raycast,
                "tiles_raster": tiles_raster,
                "tiles_raycast": tiles_raycast,
                "tiles_gs": tiles_gs,
                "plan_ms": 0.5,
            }
        )
    return out


def table(*parts):
    return pd.DataFrame([r for p in parts for r in p])


def test_tie_within_noise_is_called_a_tie():
    f = table(rows("raster", 20.0, 0.3, seed=1, tiles_raster=10, tiles_raycast=0), rows("raycast", 21.0, 0.3, seed=2))
    c = compare("raycast", f[f["policy"] == "raycast"], "raster", f[f["policy"] == "raster"])
    assert c.tie
    text = reading(f, [])[0]
    assert "within noise of it: raycast" in text
    assert "faster" not in text and "slower" not in text and "1.05x" not in text


def test_clear_difference_with_small_spread_is_called_a_difference():
    f = table(rows("raster", 10.0, 0.02, seed=1, tiles_raster=10, tiles_raycast=0), rows("raycast", 20.0, 0.02, seed=2))
    c = compare("raycast", f[f["policy"] == "raycast"], "raster", f[f["policy"] == "raster"])
    assert not c.tie and 1.9 < c.low <= c.ratio <= c.high < 2.1
    text = reading(f, [])[0]
    assert "lowest median frame time is raster's" in text
    assert "the next, raycast (20.0 ms), is 2.00x slower" in text and "within noise" not in text


def test_identical_choices_are_named_with_the_noise_verdict():
    same = table(
        rows("raycast", 20.0, 0.3, seed=2),
        rows("hybrid", 21.0, 0.3, seed=3),
        rows("raster", 30.0, 0.02, seed=1, tiles_raster=10, tiles_raycast=0),
    )
    lines = reading(same, [])
    hybrid = [l for l in lines if l.strip().startswith("hybrid")]
    assert len(hybrid) == 1
    assert "the same choices as raycast in every frame" in hybrid[0] and "difference within noise" in hybrid[0]
    # the same choices but clearly slower (small spread): a difference, with the planning cost named
    slow = table(
        rows("raycast", 20.0, 0.02, seed=2),
        rows("hybrid", 40.0, 0.02, seed=3),
        rows("raster", 30.0, 0.02, seed=1, tiles_raster=10, tiles_raycast=0),
    )
    line = next(l for l in reading(slow, []) if l.strip().startswith("hybrid"))
    assert "the same choices as raycast" in line and "yet 2.00x slower" in line and "plans each frame" in line
    # mixed choices: compared with the best pure method at the same tau, no "same choices"
    mixed = table(
        rows("raycast", 20.0, 0.02, seed=2),
        rows("raster", 30.0, 0.02, seed=1, tiles_raster=10, tiles_raycast=0),
        rows("hybrid", 10.0, 0.02, seed=3, tiles_raster=4, tiles_raycast=6),
    )
    line = next(l for l in reading(mixed, []) if l.strip().startswith("hybrid"))
    assert "same choices" not in line and "rasterizes 40 %" in line and "best pure method (raycast" in line
    assert "2.00x faster" in line and "geometry shader" not in line
    # every tile through the geometry shader is the same choices as raster_gs, not as raster
    gs = table(
        rows("raycast", 20.0, 0.02, seed=2),
        rows("raster_gs", 15.0, 0.3, seed=1, tiles_raster=10, tiles_raycast=0, tiles_gs=10),
        rows("raster", 30.0, 0.02, seed=4, tiles_raster=10, tiles_raycast=0),
        rows("hybrid", 15.5, 0.3, seed=3, tiles_raster=10, tiles_raycast=0, tiles_gs=10),
    )
    line = next(l for l in reading(gs, []) if l.strip().startswith("hybrid"))
    assert "the same choices as raster_gs in every frame" in line
    # a three-way mix names the geometry-shader share
    three = table(
        rows("raycast", 20.0, 0.02, seed=2),
        rows("raster_gs", 40.0, 0.02, seed=1, tiles_raster=10, tiles_raycast=0, tiles_gs=10),
        rows("hybrid", 10.0, 0.02, seed=3, tiles_raster=6, tiles_raycast=4, tiles_gs=2),
    )
    line = next(l for l in reading(three, []) if l.strip().startswith("hybrid"))
    assert "rasterizes 60 % of its tiles (20 % through the geometry shader)" in line


def test_repeat_matrix_and_spread():
    f = pd.DataFrame(rows("raster", 10.0, 0.2, frames=4))
    m = repeat_matrix(f)
    assert m.shape == (4, 3)
    assert 0 < repeat_spread(m) <= 0.2 * 1.1
    old = f.drop(columns="wall_ms_repeats")  # runs from before repeats were kept: medians only
    assert repeat_matrix(old).shape == (4, 1) and repeat_spread(repeat_matrix(old)) == 0


def test_frames_of_two_devices_are_never_compared():
    a = table(rows("raster", 10.0, 0.02, seed=1, tiles_raster=10, tiles_raycast=0), rows("raycast", 20.0, 0.02, seed=2))
    a["device"] = "GPU A"
    b = a.copy()
    b["device"] = "GPU B"
    b["wall_ms"] *= 10
    b["wall_ms_repeats"] = [[10 * x for x in r] for r in b["wall_ms_repeats"]]
    text = reading(pd.concat([a, b]), [])
    scenes = [line for line in text if line.startswith("**")]
    assert len(scenes) == 2 and "GPU A" in scenes[0] and "GPU B" in scenes[1]
    assert "the next, raycast (20.0 ms), is 2.00x slower" in scenes[0]
    assert "the next, raycast (200.0 ms), is 2.00x slower" in scenes[1]


def test_markdown_tables_keep_their_columns_when_a_header_or_cell_holds_a_pipe():
    """A '|' in a column name or value (as in 'median |relative error| %') is escaped: every row of the markdown
    table splits into as many cells as the header."""
    import re

    import pandas as pd

    from experiments.tables import md_table

    text = md_table(pd.DataFrame({"strategy": ["raster", "a|b"], "median |relative error| %": [17.2, 18.6]}))
    rows = text.splitlines()
    cells = [len(re.split(r"(?<!\\)\|", r)) for r in rows]
    assert len(set(cells)) == 1 and cells[0] == 4, rows
