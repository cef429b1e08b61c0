"""Exploration stops once a strategy's level is known, though its passes of a few tiles scatter too much for
their predictions to hold one by one."""

import numpy as np
from cost_helpers import columns, true_model

from hybrid.cost.online import AdaptOptions, OnlineModel

TRUE = true_model(overhead={"raster": 2.0, "raster_gs": 3.0, "raycast": 1.5}, mix_overhead=0.8)


def explored_passes(online, rng, n, sigma, tiles=2):
    """n passes of ``tiles`` ray-cast tiles, their ms TRUE's times lognormal noise of sigma, observed by the model."""
    r = TRUE.candidates.index("raycast")
    for _ in range(n):
        cols = columns(rng, tiles)
        ms = (TRUE.overhead["raycast"] + float(TRUE.predict_table(cols)[r].sum())) * float(
            np.exp(sigma * rng.standard_normal())
        )
        online.observe(cols, ["raycast"] * tiles, {"raycast": ms}, ms)


def drawn_whole(online, rng):
    """A model that drew ray casting's first pass and three whole frames of it (so it offers no more whole frames)."""
    explored_passes(online, rng, 4, sigma=0.02, tiles=20)
    assert online._broad["raycast"] >= online.options.level_rows


def offers(online, rng):
    """Of 20 frames drawn by raster where ray casting is a little dearer on every tile (so that at half its price
    it might pay) and raster_gs cannot draw, in how many the model gives ray casting a few tiles, the budget
    unbounded (a whole frame, which prices a strategy's frames where a few tiles do not, is not counted)."""
    names = TRUE.candidates
    got = 0
    for _ in range(20):
        online.credit = 1e9  # the budget is not what is tested
        table = TRUE.predict_table(columns(rng, 20))
        table[names.index("raycast")] = 1.2 * table[names.index("raster")]
        table[names.index("raster_gs")] = np.inf
        picks = np.full(table.shape[1], names.index("raster"))
        found = online.explore(table, picks, names)
        got += found is not None and found.strategy == "raycast" and len(found.tiles) <= online.options.explore_tiles
    return got


def test_a_strategy_whose_level_is_known_is_explored_no_more():
    rng = np.random.default_rng(21)
    online = OnlineModel(TRUE, AdaptOptions(explore_share=0.05))
    drawn_whole(online, rng)
    explored_passes(online, rng, 2, sigma=0.4)  # five rows: fewer than hold_rows
    assert not online.level_known("raycast") and offers(online, rng) > 0
    explored_passes(online, rng, 40, sigma=0.4)
    assert np.median(online.errors["raycast"]) > online.options.hold_error  # one by one they do not hold
    assert not online.holds("raycast")
    assert online.level_known("raycast") and offers(online, rng) == 0


def test_a_level_scattered_beyond_what_its_passes_can_tell_is_still_explored():
    rng = np.random.default_rng(22)
    online = OnlineModel(TRUE, AdaptOptions(explore_share=0.05))
    drawn_whole(online, rng)
    explored_passes(online, rng, 10, sigma=1.5)
    assert not online.level_known("raycast") and offers(online, rng) > 0
