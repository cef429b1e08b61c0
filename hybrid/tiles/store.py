"""Tile stores: the pyramid built once, out of core, into a Zarr directory, and the pyramid read back from it.

``prepare_store`` (``hybrid.tiles.store_prepare``) builds a store out of core.

``StorePyramid`` is a TilePyramid over a store: per-level bounds and errors come from the store (small arrays
read whole), a tile's samples are read from disk when asked for and kept in a host LRU cache bounded in bytes.
"""

from __future__ import annotations

import contextlib
import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.edits import Window
from hybrid.terrain.store_chunks import chunk_reader
from hybrid.terrain.stored import StoredTerrain, open_store

from .pyramid import TileKey, TilePyramid
from .pyramid_edit import touched_tiles
from .store_prepare import prepare_store  # noqa: F401  (the stores' API: prepare, then open)

HOLD_WAIT_S = 0.005  # a hold waits this long at most for the loader to finish the tile it is on
CHUNK_SHARE = 8  # decoded chunks may hold 1/CHUNK_SHARE of a StorePyramid's host budget


class StorePyramid(TilePyramid):
    """A TilePyramid over a tile store: bounds and errors from disk, tiles read on demand into a host LRU cache of
    ``host_bytes`` (default 512 MiB); thread-safe: one loader thread reads ahead what ``request`` asks for."""

    background_loader = True

    def __init__(self, terrain: StoredTerrain | str | Path, host_bytes: int = 512 << 20):
        if not isinstance(terrain, StoredTerrain):
            terrain = open_store(terrain)
        g = terrain.store
        self.hf = terrain
        self.n = int(g.attrs["tile_size"])
        self.max_level = int(g.attrs["max_level"])
        self.size = self.n * (1 << self.max_level) + 1
        self._new_caches()
        self._zmin = {l: np.asarray(g[f"zmin/{l}"][:]) for l in range(self.max_level + 1)}
        self._zmax = {l: np.asarray(g[f"zmax/{l}"][:]) for l in range(self.max_level + 1)}
        self._err = {l: np.asarray(g[f"error/{l}"][:]) for l in range(self.max_level + 1)}
        self._levels = {l: g[f"levels/{l}"] for l in range(self.max_level + 1)}
        self._readers = {l: level_reader(a, self.n) for l, a in self._levels.items()}
        self.host_budget: int = int(host_bytes)
        self._cache: OrderedDict = OrderedDict()
        self.cache_bytes = 0  # tiles and decoded chunks held, bytes (<= host_budget)
        # decoded chunks of the levels (a tile's samples span 4 of them: its own, one row and one column of two
        # neighbours and a corner), so that neighbouring tiles decode each chunk once
        self.chunk_budget: int = self.host_budget // CHUNK_SHARE
        self._chunks: OrderedDict = OrderedDict()
        self.chunk_bytes = 0
        self.stats = {"reads": 0, "hits": 0, "evictions": 0, "peak_bytes": 0, "chunk_reads": 0}
        self._lock = threading.Lock()
        self._wake = threading.Condition(threading.Lock())  # the loader thread's queue (request)
        self._wanted: list = []  # (key, whether its samples are read) in the loader's order
        self._work: dict = {}  # (key, read) -> host work the loader runs (after the samples, if read)
        self._done = threading.Event()
        self._go = threading.Event()  # cleared: the loader waits before its next tile
        self._go.set()
        self._busy = threading.Lock()  # held by the loader while it works on a tile
        self._loader: threading.Thread | None = None
        self._closing = False
        self._failed: set = set()
        self._derived: dict = {}  # key -> {product name: what derive made of its samples}, evicted with them

    def derive(self, key, name: str, make) -> None:
        """Make ``make(samples, source_step)`` of the tile's samples (a strategy's host work for its upload, such as
        the ray caster's 16-bit codes and max mipmap) and keep it beside them, counted in the host cache, until
        a Tile of ``key`` takes it (``host_products``) or the samples leave the cache; thread-safe. What was made
        while a write-through came in is dropped: it may have read node arrays that the write changed."""
        edits = self.edits
        h = self.samples(key)
        made = make(h, getattr(self.hf, "source_step", None))
        with self._lock:
            if self._cache.get(key) is h and self.edits == edits:  # made of what the tile still is
                old = self._derived.setdefault(key, {}).pop(name, None)
                self._derived[key][name] = made
                self.cache_bytes += made.nbytes - (0 if old is None else old.nbytes)
                self._evict()

    def derived_keys(self, keys, name: str) -> set:
        """Those of ``keys`` of which ``derive`` made product ``name`` that no Tile has taken yet (one lock)."""
        with self._lock:
            return {k for k in keys if name in self._derived.get(k, ())}

    def host_products(self, key) -> dict:
        """The products ``derive`` made of the tile's samples, handed over to the Tile being made (and dropped)."""
        with self._lock:
            out = self._derived.pop(key, {})
            self.cache_bytes -= sum(v.nbytes for v in out.values())
            return out

    def _drop_derived(self, key) -> None:
        """Under the lock: forget what was made of a tile's samples (they left the cache or changed)."""
        self.cache_bytes -= sum(v.nbytes for v in self._derived.pop(key, {}).values())

    def samples(self, key) -> np.ndarray:
        """The tile's (n+1)² level-l samples (float32 metres), read from disk or the host cache."""
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                self.stats["hits"] += 1
                return self._cache[key]
        win = self._window(key)
        pad = ((0, self.n + 1 - win.shape[0]), (0, self.n + 1 - win.shape[1]))
        h = win if not any(pad[0] + pad[1]) else np.ascontiguousarray(np.pad(win, pad, mode="edge"))  # win: a copy
        with self._lock:
            if key not in self._cache:
                self._cache[key] = h
                self.cache_bytes += h.nbytes
                self.stats["reads"] += 1
                self._evict()
            return self._cache[key]

    def _evict(self) -> None:
        """Under the lock: drop the oldest decoded chunks past their share (a chunk being gathered stays alive
        with its caller), then the oldest tiles (all but the newest) while tiles and chunks pass the budget."""
        while self.chunk_bytes > self.chunk_budget and self._chunks:
            _, old = self._chunks.popitem(last=False)
            self.chunk_bytes -= old.nbytes
            self.cache_bytes -= old.nbytes
        while self.cache_bytes > self.host_budget and len(self._cache) > 1:
            key, old = self._cache.popitem(last=False)
            self.cache_bytes -= old.nbytes
            self._drop_derived(key)
            self.stats["evictions"] += 1
        self.stats["peak_bytes"] = max(self.stats["peak_bytes"], self.cache_bytes)

    def _window(self, key) -> np.ndarray:
        """The tile's samples inside the level's grid (float32, up to (n+1)², fewer at the grid's last tiles),
        gathered from the decoded chunks it spans."""
        n, (R, C) = self.n, self._levels[key.level].shape
        r0, c0 = key.ty * n, key.tx * n
        rows = [self._chunk(key.level, key.ty, key.tx)]
        if r0 + n < R:
            rows.append(self._chunk(key.level, key.ty + 1, key.tx)[:1])
        win = np.concatenate(rows)
        if c0 + n < C:
            col = [self._chunk(key.level, key.ty, key.tx + 1)[:, :1]]
            if r0 + n < R:
                col.append(self._chunk(key.level, key.ty + 1, key.tx + 1)[:1, :1])
            win = np.concatenate([win, np.concatenate(col)], axis=1)
        return win

    def _chunk(self, level: int, cy: int, cx: int) -> np.ndarray:
        """Samples [cy n, (cy + 1) n) x [cx n, (cx + 1) n) of a level (float32, clipped to its grid): one chunk of
        the store, decoded once and kept in a small LRU (``chunk_budget`` bytes, counted in ``cache_bytes``)."""
        key = (level, cy, cx)
        with self._lock:
            if key in self._chunks:
                self._chunks.move_to_end(key)
                return self._chunks[key]
        c = np.asarray(self._readers[level](cy, cx), dtype=np.float32)
        with self._lock:
            self.stats["chunk_reads"] += 1
            if key in self._chunks:  # decoded meanwhile by the other thread
                return self._chunks[key]
            self._chunks[key] = c
            self.chunk_bytes += c.nbytes
            self.cache_bytes += c.nbytes
            self._evict()
            return c

    def follow_edit(self, win: Window) -> list[TileKey]:
        """Refused: a store's pyramid follows an edit written through to the store (``follow_write``)."""
        raise TerrabenchError(f"{self.hf.name!r} is a tile store: its pyramid follows a write-through (follow_write)")

    def follow_write(self, source: TilePyramid, win: Window) -> list[TileKey]:
        """Follow a write-through of the samples of ``win``: the touched tiles' bounds and errors from ``source``
        (the in-memory pyramid that was written), its host copies of them dropped, its per-level caches made
        again on next use (a few array operations a level; the quantisation bounds of every tile move when the
        store leaves its source step); returns the touched tiles."""
        keys = source.touched_keys(win)
        for level in range(self.max_level + 1):
            rows, cols = touched_tiles(source, win, level)
            at = (slice(rows.start, rows.stop), slice(cols.start, cols.stop))
            for mine, theirs in zip((self._zmin, self._zmax, self._err), source.level_arrays(level), strict=True):
                mine[level][at] = theirs[at]
        with self._lock:
            self.edits += 1
            for k in list(self._derived):  # a tile's node block also reads its neighbours' samples: all made again
                self._drop_derived(k)
            for k in keys:
                if k in self._cache:
                    self.cache_bytes -= self._cache.pop(k).nbytes
            for chunk in [c for c in self._chunks if _chunk_meets(c, self.n, win)]:
                old = self._chunks.pop(chunk)
                self.chunk_bytes -= old.nbytes
                self.cache_bytes -= old.nbytes
        self._new_caches()
        return keys

    def _on_step_tiles(self, level: int, step) -> np.ndarray:
        """Every tile of a store is on its recorded step: prepare records it only when every sample is."""
        return np.ones(self._zmin[level].shape, dtype=bool)

    def cached(self, key) -> bool:
        """Whether the tile's samples are in the host cache (or the loader failed to read them: then a read in the
        caller's thread raises the error)."""
        with self._lock:
            return key in self._cache or key in self._failed

    def cached_keys(self, keys) -> set:
        """Those of ``keys`` that ``cached`` is true of, under one hold of the lock (a frame's hundreds of tiles
        would otherwise each wait on the loader thread for the lock and the interpreter)."""
        with self._lock:
            return {k for k in keys if k in self._cache or k in self._failed}

    def request(self, keys, work: dict | None = None, later: dict | None = None) -> threading.Event:
        """Have the loader thread read these tiles next, front to back, in place of what it was asked before, and
        after a tile's samples run its ``work`` (key -> callables: host work of its upload or estimate, thread-safe,
        such as cutting a periodic extension's node block near a seam), then, once every tile is read, ``later``
        (key -> callables run without reading the tile: work no upload waits for); returns an event set when it
        is done (or was asked for others instead)."""
        work, later = work or {}, later or {}
        with self._wake:
            self._done.set()
            wanted = [k for k in dict.fromkeys(keys) if k not in self._cache or k in work]
            self._work = {(k, True): list(work[k]) for k in wanted if k in work}
            self._work.update({(k, False): list(fns) for k, fns in later.items()})
            self._wanted = [(k, True) for k in wanted] + [(k, False) for k in later]
            self._done = threading.Event()
            if not self._wanted:
                self._done.set()
            if self._loader is None:
                self._loader = threading.Thread(target=self._load, name="terrabench-tile-loader", daemon=True)
                self._loader.start()
            self._wake.notify()
            return self._done

    def idle(self, timeout: float | None = None) -> bool:
        """Wait until the loader has done what it was last asked for (tiles and their work); False on timeout."""
        with self._wake:
            done = self._done
        return done.wait(timeout)

    def failed(self, key) -> bool:
        """Whether the loader failed on the tile (its samples or its work): the caller's own read raises the error."""
        with self._lock:
            return key in self._failed

    def pause(self, paused: bool = True) -> None:
        """Hold the loader thread before its next tile (the one it is reading finishes), or let it go on: so that
        one store's background reads do not run while another store's frame is timed."""
        if paused:
            self._go.clear()
        else:
            self._go.set()

    @contextlib.contextmanager
    def held(self):
        """Hold the loader thread (as ``pause``) inside the block, once it has finished the tile it is on (waiting
        ``HOLD_WAIT_S`` at most), then restore what it was: so that a frame's upload jobs do not wait on the
        loader's reads for the interpreter lock."""
        was = not self._go.is_set()
        self.pause()
        if self._busy.acquire(timeout=HOLD_WAIT_S):  # the tile it is on done (unless slow: then it goes on)
            self._busy.release()
        try:
            yield
        finally:
            self.pause(was)

    def close(self) -> None:
        """Stop the loader thread (it ends after the tile it is reading) and drop the host cache; a later read
        reads from disk again and a later ``request`` starts a new loader."""
        with self._wake:
            self._wanted, self._work = [], {}
            self._closing = True
            self._wake.notify()
            self._go.set()
            loader, self._loader = self._loader, None
        if loader is not None:
            loader.join()
        with self._lock:
            self._cache.clear()
            self._chunks.clear()
            self._derived.clear()
            self.cache_bytes = self.chunk_bytes = 0
        self._closing = False

    def _load(self) -> None:
        """The loader thread: read the wanted tiles one at a time, front first, each with its work, until ``close``."""
        while True:
            with self._wake:
                while not self._wanted and not self._closing:
                    self._done.set()
                    self._wake.wait()
                if self._closing:
                    self._done.set()
                    return
            self._go.wait()
            with self._busy:
                with self._wake:
                    if self._closing or not self._wanted or not self._go.is_set():
                        continue  # held meanwhile: nothing starts inside a hold
                    key, read = item = self._wanted.pop(0)
                    work = self._work.pop(item, ())
                try:
                    if read:
                        self.samples(key)
                    for fn in work:
                        fn()
                except Exception:  # the renderer's own read of it raises the error where it is seen
                    with self._lock:
                        self._failed.add(key)

    @property
    def padded(self) -> np.ndarray:
        """Refused: a stored terrain is never gathered into one square."""
        raise TerrabenchError(
            f"{self.hf.name!r} is a tile store: its padded grid is never built whole (the raster "
            "strategies read the store's node arrays instead)"
        )


def _chunk_meets(chunk: tuple, n: int, win: Window) -> bool:
    """Whether a StorePyramid's decoded chunk (level, cy, cx) holds samples of a window of level-0 samples."""
    level, cy, cx = chunk
    s, k = n << level, 1 << level  # a level's last sample may sit up to k samples before
    return cy * s - k < win.i1 and win.i0 < (cy + 1) * s and cx * s - k < win.j1 and win.j0 < (cx + 1) * s


def level_reader(array, n: int):
    """Chunk (cy, cx) of n x n samples of a level's grid: a periodic extension's wrapped level reads its source's
    chunk, a store's level decodes its chunk file directly (``hybrid.terrain.store_chunks``)."""
    wrapped = getattr(array, "chunk_reader", None)
    return wrapped(n) if wrapped is not None else chunk_reader(array, (n, n))


def pyramid_for(hf, tile_size: int) -> TilePyramid:
    """The pyramid of a terrain: a StorePyramid for a tile store (its own tile size, which ``tile_size`` must
    match), else an in-memory TilePyramid."""
    if isinstance(hf, StoredTerrain):
        n = int(hf.store.attrs["tile_size"])
        if int(tile_size) != n:
            raise TerrabenchError(
                f"{hf.path} was prepared with tiles of {n} cells; use --tile-size {n} (or prepare "
                f"it again with --tile-size {tile_size})"
            )
        return StorePyramid(hf)
    return TilePyramid(hf, tile_size)
