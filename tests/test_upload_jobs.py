"""Upload jobs within a frame's budget (hybrid.uploads.stream_uploads), on a clock the jobs themselves advance: after
the first job a frame starts only jobs whose expected time fits in what is left, several a frame, and the tiles
whose fallback shows the largest screen-space error go first."""

from types import SimpleNamespace

import pytest

from hybrid import uploads
from hybrid.residency import ResidencyCache
from hybrid.tiles.pyramid import TileKey
from hybrid.uploads import JobCosts, stream_uploads

MAX_LEVEL = 3


class Clock:
    """A perf_counter in seconds that only the fake uploads advance."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


class FakeStrategy:
    """Uploads that take ``ms`` on the clock and record which tile they were."""

    def __init__(self, clock: Clock, ms: float):
        self.clock, self.ms, self.uploaded = clock, ms, []

    def upload(self, key):
        self.clock.now += self.ms / 1e3
        self.uploaded.append(key)
        return SimpleNamespace(nbytes=100, release=lambda: None)


def plan(level: int, tx: int, ty: int, distance: float):
    return SimpleNamespace(key=TileKey(level, tx, ty), choice="s", selected=SimpleNamespace(distance=distance))


@pytest.fixture
def clock(monkeypatch):
    c = Clock()
    monkeypatch.setattr(uploads.time, "perf_counter", c)
    return c


def _frame(cache, strategy, plans, budget, costs, error_of=None):
    return stream_uploads(
        cache, {"s": strategy}, plans, set(), lambda k: k, MAX_LEVEL, budget, error_of=error_of, costs=costs
    )


@pytest.mark.parametrize("job_ms, per_frame", [(3.0, 2), (2.0, 4), (1.5, 5), (9.0, 1)])
def test_jobs_start_only_if_they_fit_and_several_fit_a_frame(clock, job_ms, per_frame):
    strategy, cache, costs = FakeStrategy(clock, job_ms), ResidencyCache(), JobCosts()
    plans = [plan(0, x, y, 10.0 + x + 8 * y) for y in range(8) for x in range(8)]
    _frame(cache, strategy, plans, 8.5, costs)  # the root and jobs of a cost not yet known: the first measures it
    counts = []
    while len(cache.entries) < len(plans) + 1:
        before = clock.now
        report = _frame(cache, strategy, plans, 8.5, costs)
        assert report.upload_ms == pytest.approx((clock.now - before) * 1e3)
        assert report.upload_ms <= 8.5 or report.uploads == 1, report  # only a lone first job may pass it
        counts.append(report.uploads)
        assert report.fallback_tiles == len(plans) + 1 - len(cache.entries)
    assert counts[:-1] == [per_frame] * (len(counts) - 1) and 0 < counts[-1] <= per_frame
    assert costs.expect(("s", True)) == pytest.approx(job_ms)


def test_the_largest_fallback_error_goes_first(clock):
    strategy, cache, costs = FakeStrategy(clock, 1.0), ResidencyCache(), JobCosts()
    errors = {0: 0.0, 1: 0.5, 2: 2.0, 3: 8.0}  # metres by level
    near = plan(0, 0, 0, 10.0)  # its parent (1, 0, 0) resident: a fallback of 0.5 m at 10 m
    far = plan(0, 7, 7, 40.0)  # only the root above it: 8 m at 40 m
    mid = plan(0, 4, 0, 20.0)  # its grandparent (2, 1, 0) resident: 2 m at 20 m
    sibling = plan(0, 5, 1, 25.0)  # the same parent (1, 2, 0) as mid, found once: 2 m at 25 m
    for key in (TileKey(1, 0, 0), TileKey(2, 1, 0)):
        cache.get("s", strategy, key, lambda key=key: key)
    plans = [near, mid, sibling, far]  # front to back
    order = []
    for _ in range(5):  # a zero budget: one job a frame (the root's first)
        strategy.uploaded.clear()
        _frame(cache, strategy, plans, 0.0, costs, error_of=lambda k: errors[k.level])
        order += [k for k in strategy.uploaded if k.level == 0]
    assert order == [far.key, mid.key, sibling.key, near.key]  # 0.2, 0.1, 0.08, 0.05 m a metre
    cache.clear()
    strategy.uploaded.clear()
    _frame(cache, strategy, plans, 0.0, costs)  # without errors: front to back
    _frame(cache, strategy, plans, 0.0, costs)
    assert strategy.uploaded[-1] == near.key
