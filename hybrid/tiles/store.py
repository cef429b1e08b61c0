"""Tile stores: the pyramid built once, out of core, into a Zarr directory, and the pyramid read back from it.

``prepare_store`` reads a grid source (``hybrid.terrain.grid_sources``) one band of tile rows at a time and
writes every level's samples (level l keeps every 2^l-th level-0 sample and the last row and column, as
``TilePyramid.tile`` gathers them), each tile's height bounds and its geometric error. Errors are exact, as the
in-memory pyramid's, for levels whose tiles span at most EXACT_SPAN level-0 cells (measured against level 0's
samples, read in pieces); above, a level's error is bounded without level 0 in memory: the coarser surface S_l differs
from level 0 by at most max |S_l - S_(l-1)| (taken at level l-1's samples: both surfaces split cells along the
same diagonal, so S_(l-1)'s triangles refine S_l's and the largest difference sits at a vertex) plus the
children's error. The bound is never below the exact error (tested), so the screen-space bound still holds;
it may refine a little more than the exact error would. Then the raster strategies' node arrays are written
(``store_nodes.build_nodes``; a complete store without them gets them when prepared again). A source's
``source_step`` is recorded in the attributes (``[step, offset]``, or null) when every level-0 sample lies on it, so
the ray caster's 16-bit tiles of the store are exact, as the in-memory grid's are. Progress is kept in
the store's attributes after every band, so an interrupted prepare resumes where it stopped; the store is marked
complete last.

``StorePyramid`` is a TilePyramid over a store: per-level bounds and errors come from the store (small arrays
read whole), a tile's samples are read from disk when asked for and kept in a host LRU cache bounded in bytes.
"""
from __future__ import annotations

import threading
import time
from collections import OrderedDict
from pathlib import Path

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.stored import STORE_FORMAT, STORE_VERSION, StoredTerrain, _zarr, is_store, open_store

from .fans import GPU_BETA
from .pyramid import TilePyramid, _block_reduce, interpolate_clamped
from .quantize import on_step_cells
from .store_blocks import build_blocks
from .store_nodes import build_nodes, node_bands, node_square

COL_BLOCK = 4096                # about this many columns per piece of a band when measuring errors (memory bound)
CHUNK_SHARE = 8                 # decoded chunks may hold 1/CHUNK_SHARE of a StorePyramid's host budget
EXACT_SPAN = 1024               # levels whose tiles span at most this many level-0 cells get exact errors


def _levels(rows: int, cols: int, n: int) -> int:
    tiles0 = -(-(max(rows, cols) - 1) // n)
    return int(np.ceil(np.log2(tiles0))) if tiles0 > 1 else 0


def _level_shape(rows: int, cols: int, level: int) -> tuple[int, int]:
    k = 1 << level
    return -(-(rows - 1) // k) + 1, -(-(cols - 1) // k) + 1


def _tile_reduce(band: np.ndarray, n: int, fn) -> np.ndarray:
    """Per tile of a band of samples (first row = the tile row's first), fn over its (n+1)-sample span of columns
    and all the band's rows: (tiles across,)."""
    m = fn.reduce(band, axis=0)
    starts = np.arange(0, len(m) - 1, n)
    ends = np.minimum(starts + n, len(m) - 1)
    return fn(fn.reduceat(m, starts), m[ends])


class _Progress:
    def __init__(self, report, total: int):
        self.report, self.total, self.done, self.t0 = report, total, 0, time.perf_counter()

    def step(self, what: str) -> None:
        self.done += 1
        if self.report:
            self.report(self.done, self.total, what, time.perf_counter() - self.t0)


def prepare_store(source, out, tile_size: int = 256, report=None, stop_after: int | None = None) -> Path:
    """Build the tile store of a grid source, node arrays included, into directory ``out`` (resuming an interrupted
    build of the same source); ``report(done, total, what, seconds)`` is called after every band. ``stop_after`` bands (tests)
    raises KeyboardInterrupt, as an interruption would."""
    zarr = _zarr()
    n = int(tile_size)
    if n < 2 or n & (n - 1):
        raise TerrabenchError(f"tile size must be a power of two >= 2 cells, got {tile_size!r}")
    rows, cols = int(source.rows), int(source.cols)
    if rows < 2 or cols < 2:
        raise TerrabenchError(f"{source.name}: a grid needs at least 2x2 samples, got {rows}x{cols}")
    sx, sy = (source.spacing, source.spacing) if np.isscalar(source.spacing) else tuple(source.spacing)
    params = {"source": getattr(source, "path", source.name), "rows": rows, "cols": cols, "tile_size": n,
              "spacing": [float(sx), float(sy)]}
    out = Path(out)
    if out.exists() and not is_store(out):
        if any(out.iterdir()):
            raise TerrabenchError(f"{out}: exists and is not a tile store; choose an empty or new folder")
    if is_store(out):
        g = zarr.open_group(str(out), mode="r+")
        if dict(g.attrs).get("params") != params:
            raise TerrabenchError(f"{out}: holds a store of other input or settings ({dict(g.attrs).get('params')}); "
                                  "choose another folder or remove it")
        if g.attrs.get("complete") and g.attrs.get("nodes") and g.attrs.get("node_blocks"):
            return out
    else:
        g = zarr.open_group(str(out), mode="w")
        g.attrs.update({"format": STORE_FORMAT, "version": STORE_VERSION, "complete": False, "params": params,
                        "name": source.name, "spacing": [float(sx), float(sy)], "origin": [0.0, 0.0, 0.0],
                        "tile_size": n, "max_level": _levels(rows, cols, n), "notes": list(source.notes),
                        "made_by": f"terrabench prepare, tiles of {n}", "progress": {}, "height_range": None,
                        "source_step": _claimed_step(source)})
    L = int(g.attrs["max_level"])
    bands = sum(-(-(_level_shape(rows, cols, l)[0] - 1) // n) for l in range(L + 1))
    prog = _Progress(report, 2 * bands + node_bands(node_square(n, L)[0]))   # levels, nodes, blocks
    stop = [stop_after]

    def mark(key: str, count: int, what: str, extra: dict | None = None):
        p = dict(g.attrs["progress"])
        p[key] = count
        g.attrs.update({"progress": p, **(extra or {})})
        prog.step(what)
        if stop[0] is not None:
            stop[0] -= 1
            if stop[0] <= 0:
                raise KeyboardInterrupt("stopped as asked (stop_after)")

    def band_done(level: int, ty: int, extra: dict | None = None):
        mark(str(level), ty + 1, f"level {level} band {ty + 1}", extra)

    for level in range(L + 1):
        R, C = _level_shape(rows, cols, level)
        ty_n, tx_n = -(-(R - 1) // n), -(-(C - 1) // n)
        arrays = {}
        for name, shape, chunks, fill in ((f"levels/{level}", (R, C), (n, n), np.nan),
                                          (f"zmin/{level}", (ty_n, tx_n), (ty_n, tx_n), np.nan),
                                          (f"zmax/{level}", (ty_n, tx_n), (ty_n, tx_n), np.nan),
                                          (f"error/{level}", (ty_n, tx_n), (ty_n, tx_n), np.nan)):
            arrays[name.split("/")[0]] = g[name] if name in g else g.create_array(
                name, shape=shape, chunks=chunks, dtype="f4" if name.startswith("levels") else "f8", fill_value=fill)
        lv, zmin, zmax, err = arrays["levels"], arrays["zmin"], arrays["zmax"], arrays["error"]
        start = int(dict(g.attrs["progress"]).get(str(level), 0))
        prev = g[f"levels/{level - 1}"] if level else None
        prev_err = np.asarray(g[f"error/{level - 1}"][:]) if level else None
        R1 = _level_shape(rows, cols, level - 1)[0] if level else rows
        for ty in range(start, ty_n):
            r0, r1 = ty * n, min(ty * n + n + 1, R)
            if level == 0:
                band = source.read_rows(r0, r1)
                own = np.zeros(tx_n)
                step = g.attrs.get("source_step")
                if step and not on_step_cells(band, step).all():   # a claimed step the samples are not on
                    g.attrs.update({"source_step": None})
            else:
                a0, a1 = 2 * r0, min(2 * (r1 - 1), R1 - 1) + 1      # level l-1 rows under the band
                fine = np.asarray(prev[a0:a1, :], dtype=np.float32)
                idx = np.minimum(2 * np.arange(r1 - r0), a1 - a0 - 1)
                cidx = np.minimum(2 * np.arange(C), fine.shape[1] - 1)
                band = fine[np.ix_(idx, cidx)]
                if (n << level) <= EXACT_SPAN:             # exact: against level 0's samples under the band
                    k = 1 << level
                    b0, b1 = r0 * k, min((r1 - 1) * k, rows - 1) + 1
                    level0 = g["levels/0"]
                    own = _band_error(lambda c0, c1: level0[b0:b1, c0:c1], cols, k, n)
                else:                                      # bounded: against level l-1, plus its error
                    own = _band_error(lambda c0, c1: fine[:, c0:c1], fine.shape[1], 2, n)
            lv[r0:r1, :] = band
            if level == 0:
                zmin[ty, :] = _tile_reduce(band, n, np.minimum)
                zmax[ty, :] = _tile_reduce(band, n, np.maximum)
            if level:
                kids = _block_reduce(prev_err, 2, np.maximum)[ty]
                err[ty, :] = np.maximum(own, kids) if (n << level) <= EXACT_SPAN else own + kids
            else:
                err[ty, :] = own
            hr = g.attrs["height_range"]
            lo, hi = float(band.min()), float(band.max())
            band_done(level, ty, {"height_range": [min(lo, hr[0]), max(hi, hr[1])] if hr else [lo, hi]}
                      if level == 0 else None)
        if level:                                          # bounds of a level: its children's, 2 x 2
            zmin[:, :] = _block_reduce(np.asarray(g[f"zmin/{level - 1}"][:]), 2, np.minimum)
            zmax[:, :] = _block_reduce(np.asarray(g[f"zmax/{level - 1}"][:]), 2, np.maximum)
    build_nodes(g, rows, cols, n, L, GPU_BETA, mark)
    build_blocks(g, n, L, mark)
    g.attrs.update({"complete": True})
    return out


def _claimed_step(source) -> list | None:
    """The source's ``source_step`` as [step, offset] metres (checked: finite, step > 0), or None."""
    step = getattr(source, "source_step", None)
    if step is None:
        return None
    try:
        s, o = (float(v) for v in step)
    except (TypeError, ValueError):
        raise TerrabenchError(f"{source.name}: source_step must be (step, offset) in metres, got {step!r}") from None
    if not (np.isfinite(s) and np.isfinite(o) and s > 0):
        raise TerrabenchError(f"{source.name}: source_step must have a finite step > 0 and a finite offset (metres), "
                              f"got {step!r}")
    return [s, o]


def _band_error(piece_of, cols: int, k: int, n: int) -> np.ndarray:
    """Per level-l tile of a band: the largest |S - G| (metres) over the samples G of a finer grid under the band,
    S the grid of every k-th of them triangulated; ``piece_of(c0, c1)`` gives columns c0..c1-1 of the band's
    rows of that grid (first row on a level-l row). Read in pieces of whole tiles to bound memory."""
    span = k * n                                             # finer-grid cells a level-l tile spans
    tiles = -(-(cols - 1) // span) if cols > 1 else 1
    out = np.zeros(tiles)
    width = span * max(1, COL_BLOCK // span)
    for c0 in range(0, max(cols - 1, 1), width):
        c1 = min(c0 + width, cols - 1) + 1
        piece = np.asarray(piece_of(c0, c1), dtype=np.float64)
        dev = np.abs(interpolate_clamped(piece, k) - piece)
        if piece.shape[0] > 1 and piece.shape[1] > 1:
            cell = np.maximum(np.maximum(dev[:-1, :-1], dev[:-1, 1:]), np.maximum(dev[1:, :-1], dev[1:, 1:]))
        else:
            cell = dev
        e = _block_reduce(cell, span, np.maximum).max(axis=0)
        t0 = c0 // span
        out[t0:t0 + len(e)] = np.maximum(out[t0:t0 + len(e)], e)
    return out


class StorePyramid(TilePyramid):
    """A TilePyramid over a tile store: bounds and errors from disk, tiles read on demand into a host LRU cache of
    ``host_bytes`` (default 512 MiB); thread-safe: one loader thread reads ahead what ``request`` asks for."""

    def __init__(self, terrain: StoredTerrain | str | Path, host_bytes: int = 512 << 20):
        if not isinstance(terrain, StoredTerrain):
            terrain = open_store(terrain)
        g = terrain.store
        self.hf = terrain
        self.n = int(g.attrs["tile_size"])
        self.max_level = int(g.attrs["max_level"])
        self.size = self.n * (1 << self.max_level) + 1
        self._boxes: dict = {}
        self._qerr: dict = {}
        self._zmin = {l: np.asarray(g[f"zmin/{l}"][:]) for l in range(self.max_level + 1)}
        self._zmax = {l: np.asarray(g[f"zmax/{l}"][:]) for l in range(self.max_level + 1)}
        self._err = {l: np.asarray(g[f"error/{l}"][:]) for l in range(self.max_level + 1)}
        self._levels = {l: g[f"levels/{l}"] for l in range(self.max_level + 1)}
        self.host_budget = int(host_bytes)
        self._cache: OrderedDict = OrderedDict()
        self.cache_bytes = 0                      # tiles and decoded chunks held, bytes (<= host_budget)
        # decoded chunks of the levels (a tile's samples span 4 of them: its own, one row and one column of two
        # neighbours and a corner), so that neighbouring tiles decode each chunk once
        self.chunk_budget = self.host_budget // CHUNK_SHARE
        self._chunks: OrderedDict = OrderedDict()
        self.chunk_bytes = 0
        self.stats = {"reads": 0, "hits": 0, "evictions": 0, "peak_bytes": 0, "chunk_reads": 0}
        self._lock = threading.Lock()
        self._wake = threading.Condition(threading.Lock())   # the loader thread's queue (request)
        self._wanted: list = []
        self._done = threading.Event()
        self._go = threading.Event()                          # cleared: the loader waits before its next tile
        self._go.set()
        self._loader = None
        self._closing = False
        self._failed: set = set()

    def samples(self, key) -> np.ndarray:
        """The tile's (n+1)² level-l samples (float32 metres), read from disk or the host cache."""
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                self.stats["hits"] += 1
                return self._cache[key]
        win = self._window(key)
        pad = ((0, self.n + 1 - win.shape[0]), (0, self.n + 1 - win.shape[1]))
        h = np.ascontiguousarray(np.pad(win, pad, mode="edge"))
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
            _, old = self._cache.popitem(last=False)
            self.cache_bytes -= old.nbytes
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
        n = self.n
        c = np.asarray(self._levels[level][cy * n:(cy + 1) * n, cx * n:(cx + 1) * n], dtype=np.float32)
        with self._lock:
            self.stats["chunk_reads"] += 1
            if key in self._chunks:                  # decoded meanwhile by the other thread
                return self._chunks[key]
            self._chunks[key] = c
            self.chunk_bytes += c.nbytes
            self.cache_bytes += c.nbytes
            self._evict()
            return c

    def _on_step_tiles(self, level: int, step) -> np.ndarray:
        """Every tile of a store is on its recorded step: prepare records it only when every sample is."""
        return np.ones(self._zmin[level].shape, dtype=bool)

    def cached(self, key) -> bool:
        """Whether the tile's samples are in the host cache (or the loader failed to read them: then a read in the
        caller's thread raises the error)."""
        with self._lock:
            return key in self._cache or key in self._failed

    def request(self, keys) -> threading.Event:
        """Have the loader thread read these tiles next, front to back, in place of what it was asked before;
        returns an event set when it has read them (or was asked for others instead)."""
        with self._wake:
            self._done.set()
            self._wanted = [k for k in dict.fromkeys(keys) if k not in self._cache]
            self._done = threading.Event()
            if not self._wanted:
                self._done.set()
            if self._loader is None:
                self._loader = threading.Thread(target=self._load, name="terrabench-tile-loader", daemon=True)
                self._loader.start()
            self._wake.notify()
            return self._done

    def pause(self, paused: bool = True) -> None:
        """Hold the loader thread before its next tile (the one it is reading finishes), or let it go on: so that
        one store's background reads do not run while another store's frame is timed."""
        if paused:
            self._go.clear()
        else:
            self._go.set()

    def close(self) -> None:
        """Stop the loader thread (it ends after the tile it is reading) and drop the host cache; a later read
        reads from disk again and a later ``request`` starts a new loader."""
        with self._wake:
            self._wanted = []
            self._closing = True
            self._wake.notify()
            self._go.set()
            loader, self._loader = self._loader, None
        if loader is not None:
            loader.join()
        with self._lock:
            self._cache.clear()
            self._chunks.clear()
            self.cache_bytes = self.chunk_bytes = 0
        self._closing = False

    def _load(self) -> None:
        """The loader thread: read the wanted tiles one at a time, front first, until ``close``."""
        while True:
            with self._wake:
                while not self._wanted and not self._closing:
                    self._done.set()
                    self._wake.wait()
                if self._closing:
                    self._done.set()
                    return
            self._go.wait()
            with self._wake:
                if self._closing or not self._wanted:
                    continue
                key = self._wanted.pop(0)
            try:
                self.samples(key)
            except Exception:                # the renderer's own read of it raises the error where it is seen
                with self._lock:
                    self._failed.add(key)

    @property
    def padded(self) -> np.ndarray:
        """Refused: a stored terrain is never gathered into one square."""
        raise TerrabenchError(f"{self.hf.name!r} is a tile store: its padded grid is never built whole (the raster "
                              "strategies read the store's node arrays instead)")


def pyramid_for(hf, tile_size: int) -> TilePyramid:
    """The pyramid of a terrain: a StorePyramid for a tile store (its own tile size, which ``tile_size`` must
    match), else an in-memory TilePyramid."""
    if isinstance(hf, StoredTerrain):
        n = int(hf.store.attrs["tile_size"])
        if int(tile_size) != n:
            raise TerrabenchError(f"{hf.path} was prepared with tiles of {n} cells; use --tile-size {n} (or prepare "
                                  f"it again with --tile-size {tile_size})")
        return StorePyramid(hf)
    return TilePyramid(hf, tile_size)
