"""GPU residency of uploaded tiles: a byte budget with least-recently-used eviction.

Each entry is one tile uploaded by one strategy; its size is the strategy's exact ``nbytes`` (the sum of
the buffers and textures it allocated). A resident tile is never uploaded again; when an upload would pass
the budget, the least recently used entries not needed by the current frame are released first.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

from hybrid.errors import TerrabenchError


class BudgetExceeded(TerrabenchError):
    """An upload that does not fit in the GPU byte budget beside the tiles the frame pins."""


@dataclass
class ResidencyStats:
    """Counters since the cache was made."""

    uploads: int = 0
    hits: int = 0
    evictions: int = 0
    peak_bytes: int = 0


class ResidencyCache:
    """Uploaded tiles keyed by (strategy name, tile key), within ``budget_bytes`` (None = unlimited)."""

    def __init__(self, budget_bytes: int | None = None):
        if budget_bytes is not None and (not isinstance(budget_bytes, int) or budget_bytes <= 0):
            raise TerrabenchError(f"GPU memory budget must be a positive number of bytes, got {budget_bytes!r}")
        self.budget = budget_bytes
        self.entries: OrderedDict = OrderedDict()
        self.bytes = 0
        self.stats = ResidencyStats()

    def get(self, strategy_name: str, strategy, tile_key, make_tile, pinned: set | frozenset = frozenset()):
        """The resident GPU tile for (strategy, key), uploading ``make_tile()`` if absent; pinned keys stay."""
        k = (strategy_name, tile_key)
        if k in self.entries:
            self.entries.move_to_end(k)
            self.stats.hits += 1
            return self.entries[k]
        gpu = strategy.upload(make_tile())
        size = int(gpu.nbytes)
        if self.budget is not None and self.bytes + size > self.budget:
            need, victims = self.bytes + size - self.budget, []
            for old, tile in self.entries.items():  # least recently used first, pinned ones kept
                if need <= 0:
                    break
                if old not in pinned:
                    victims.append(old)
                    need -= int(tile.nbytes)
            for old in victims:
                self._evict(old)
            if self.bytes + size > self.budget:
                gpu.release()
                raise BudgetExceeded(
                    f"GPU memory budget of {self.budget} bytes is too small for this frame: the tiles it needs "
                    f"take {self.bytes + size} bytes; raise the budget"
                )
        self.entries[k] = gpu
        self.bytes += size
        self.stats.uploads += 1
        self.stats.peak_bytes = max(self.stats.peak_bytes, self.bytes)
        return gpu

    def _evict(self, k) -> None:
        gpu = self.entries.pop(k)
        self.bytes -= int(gpu.nbytes)
        gpu.release()
        self.stats.evictions += 1

    def resident(self, strategy_name: str) -> list[tuple]:
        """(tile key, GPU tile) of every tile resident for one strategy, least recently used first."""
        return [(key, gpu) for (name, key), gpu in self.entries.items() if name == strategy_name]

    def replace(self, strategy_name: str, tile_key, gpu) -> None:
        """Put ``gpu`` in place of the resident tile (strategy, key), keeping its place in the LRU order, and free
        the old one (its tile changed: an edit); the budget is not checked (a tile of the same shape)."""
        k = (strategy_name, tile_key)
        old = self.entries[k]
        self.entries[k] = gpu
        self.bytes += int(gpu.nbytes) - int(old.nbytes)
        self.stats.peak_bytes = max(self.stats.peak_bytes, self.bytes)
        old.release()

    def bytes_by_strategy(self) -> dict[str, int]:
        """Resident bytes per strategy name."""
        out: dict[str, int] = {}
        for (name, _), gpu in self.entries.items():
            out[name] = out.get(name, 0) + int(gpu.nbytes)
        return out

    def clear(self) -> None:
        """Release every resident tile."""
        for k in list(self.entries):
            self._evict(k)
        self.stats.evictions = 0


def reserve_pools(strategies: dict, budget_bytes: int, pyramid) -> None:
    """Have the strategies that keep their tiles in pools (``reserve(n, nbytes, tiles)``: the raster heaps) hold
    the resident tiles' GPU budget from the start, and no more than room for every tile of the pyramid, so that a
    streaming frame never pays for a pool's growth. Strategies that can share a pool (``share_heaps``: the two
    raster strategies of a hybrid) fill one of the whole budget, which either may fill alone however the choices
    lean; others each hold an even share."""
    pooled = [s for s in strategies.values() if callable(getattr(s, "reserve", None))]
    if not pooled:
        return
    tiles = sum(r * c for r, c in (pyramid.tile_counts(level) for level in range(pyramid.max_level + 1)))
    owner, rest = pooled[0], pooled[1:]
    key = getattr(owner, "heap_key", None)
    sharing = [s for s in rest if key is not None and getattr(s, "heap_key", None) == key]
    for s in sharing:
        s.share_heaps(owner)
    alone = [owner] + [s for s in rest if s not in sharing]
    for s in alone:
        s.reserve(pyramid.n, budget_bytes // len(alone), tiles)
