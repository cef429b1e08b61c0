"""A thread-safe least-recently-used store of arrays bounded in bytes, each made on its first miss."""

from __future__ import annotations

import threading
from collections import OrderedDict


class ByteLRU:
    """Arrays by key, least recently used out once their bytes pass ``budget`` (the newest always stays); ``get``
    makes a missing one outside the lock, so two threads may make the same array and the first kept wins."""

    def __init__(self, budget: int):
        self.budget = int(budget)
        self.nbytes, self.made = 0, 0  # bytes held; arrays kept since the start
        self._items: OrderedDict = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key, make):
        """The array of ``key``, made by ``make()`` if it is not held."""
        with self._lock:
            hit = self._items.get(key)
            if hit is not None:
                self._items.move_to_end(key)
                return hit
        value = make()
        with self._lock:
            if key not in self._items:
                self._items[key] = value
                self.nbytes += value.nbytes
                self.made += 1
                while self.nbytes > self.budget and len(self._items) > 1:
                    _, old = self._items.popitem(last=False)
                    self.nbytes -= old.nbytes
            return self._items[key]

    def __contains__(self, key) -> bool:
        with self._lock:
            return key in self._items

    def __len__(self) -> int:
        with self._lock:
            return len(self._items)

    def clear(self) -> None:
        """Drop every array."""
        with self._lock:
            self._items.clear()
            self.nbytes = 0
