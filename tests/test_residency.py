"""The GPU tile cache's eviction: least recently used first, pinned tiles kept, only as many as the new tile needs."""

import pytest

from hybrid.residency import BudgetExceeded, ResidencyCache


class _Gpu:
    def __init__(self, nbytes):
        self.nbytes, self.released = nbytes, False

    def release(self):
        self.released = True


class _Strategy:
    def upload(self, tile):
        return _Gpu(tile)


def test_eviction_takes_the_least_recent_unpinned_tiles_until_the_new_one_fits():
    cache, s = ResidencyCache(100), _Strategy()
    tiles = {k: cache.get("r", s, k, lambda: 30) for k in "abc"}  # 90 bytes
    cache.get("r", s, "a", lambda: 0)  # a hit: a is now the most recent
    cache.get("r", s, "d", lambda: 40, pinned={("r", "b")})  # needs 30 more: c goes (b pinned, a recent)
    assert list(cache.entries) == [("r", "b"), ("r", "a"), ("r", "d")] and cache.bytes == 100
    assert tiles["c"].released and not tiles["a"].released and cache.stats.evictions == 1
    cache.get("r", s, "e", lambda: 60, pinned={("r", "d")})  # 60 more: b and a both go
    assert list(cache.entries) == [("r", "d"), ("r", "e")] and cache.bytes == 100
    with pytest.raises(BudgetExceeded):
        cache.get("r", s, "f", lambda: 50, pinned={("r", "d"), ("r", "e")})
