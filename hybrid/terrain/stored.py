"""A terrain whose samples stay on disk: a tile store written by ``terrabench prepare`` (hybrid.tiles.store).

The store is a Zarr v3 group (a directory): ``levels/<l>`` holds the pyramid's level-l sample grid (every
2^l-th level-0 sample, the last row and column kept, chunks of one tile's cells), ``zmin/<l>``, ``zmax/<l>``
and ``error/<l>`` the per-tile bounds and geometric errors, ``nodes/effective|zlo|zhi/<g>`` the raster
strategies' node arrays (hybrid.tiles.store_nodes), and the group's attributes the header (format, version, name,
spacing, origin, CRS, height range, tile size, how it was made, the node arrays' parameters under ``nodes``, the
source's height step ``source_step`` as [step, offset] metres or null, and whether it is complete). A store written
before ``source_step`` was recorded lacks the attribute and reads as null (no step). ``manifest.json`` lists every
other file's size and CRC-32 (``hybrid.terrain.store_manifest``): ``open_store`` reads the store through a Zarr store
that checks every listed file it reads, so a missing, short or altered chunk is one named error, never fill values.
Zarr was chosen over a COG with overviews because every level is a plain chunked array with its own per-tile
tables beside it in one self-describing directory, written and read a window at a time from Python with no
GDAL driver in the loop, and resumable chunk by chunk.

``StoredTerrain`` is a HeightField whose ``heights`` is a ``LazyGrid``: indexing it reads only the chunks the
index touches, so camera presets, ground heights and edge profiles work without loading the grid; whatever
would need the whole grid at once (the reference renderer, ``load``) refuses by name beyond MAX_LOAD_SAMPLES; the
raster strategies read their node arrays from the store a tile at a time.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import HeightField, spacing_pair
from hybrid.terrain.store_journal import recover
from hybrid.terrain.store_manifest import (
    MANIFEST,
    bad_files,
    checked_store,
    damaged,
    load_manifest,
)

STORE_FORMAT = "terrabench-tile-store"
STORE_VERSION = 1
MAX_LOAD_SAMPLES = 1 << 26  # a stored grid up to this many samples may be loaded whole (256 MiB)


def _zarr():
    try:
        import zarr
    except ImportError:  # pragma: no cover - a declared dependency
        raise TerrabenchError("tile stores need zarr (pip install zarr)") from None
    return zarr


def is_store(path) -> bool:
    """True if path is a directory holding a terrabench tile store (complete or not)."""
    p = Path(path)
    if not (p / "zarr.json").is_file():
        return False
    try:
        import json

        return json.loads((p / "zarr.json").read_text()).get("attributes", {}).get("format") == STORE_FORMAT
    except (OSError, ValueError):
        return False


class LazyGrid:
    """A read-only 2-D view of a stored sample grid (float32 metres, rows south to north) that reads only the
    chunks an index touches; slices, integers and (broadcast) integer arrays as numpy does."""

    def __init__(self, array, height_range: tuple[float, float], name: str):
        self.array, self.range, self.name = array, height_range, name
        self.shape = tuple(int(s) for s in array.shape)
        self.dtype = np.dtype(np.float32)
        self.ndim = 2

    @property
    def size(self) -> int:
        """Number of samples."""
        return self.shape[0] * self.shape[1]

    def __getitem__(self, index):
        if not isinstance(index, tuple):
            index = (index, slice(None))
        if any(isinstance(i, (np.ndarray, list)) for i in index):
            i, j = np.broadcast_arrays(
                *(
                    np.asarray(k, dtype=np.int64) if not isinstance(k, slice) else np.arange(self.shape[d])[k]
                    for d, k in enumerate(index)
                )
            )
            i = np.where(i < 0, i + self.shape[0], i)
            j = np.where(j < 0, j + self.shape[1], j)
            if i.size == 0:
                return np.zeros(i.shape, np.float32)
            flat = np.asarray(self.array.vindex[i.ravel(), j.ravel()], dtype=np.float32)
            return flat.reshape(i.shape)
        return np.asarray(self.array[index], dtype=np.float32)

    def min(self) -> float:
        """Lowest stored height (metres, from the store's header)."""
        return self.range[0]

    def max(self) -> float:
        """Highest stored height (metres, from the store's header)."""
        return self.range[1]

    def mean(self) -> float:
        """Midpoint of the height range (the mean would need every sample)."""
        return 0.5 * (self.range[0] + self.range[1])

    def __array__(self, dtype=None, copy=None):
        if self.size > MAX_LOAD_SAMPLES:
            raise TerrabenchError(
                f"{self.name!r} is stored out of core ({self.shape[1]}x{self.shape[0]} samples); this step needs "
                f"the whole grid in memory, allowed up to {MAX_LOAD_SAMPLES} samples"
            )
        a = np.asarray(self.array[:, :], dtype=np.float32)
        return a if dtype is None else a.astype(dtype)

    def astype(self, dtype, copy=True) -> np.ndarray:
        """The whole grid in memory as dtype (numpy's astype; refused beyond MAX_LOAD_SAMPLES as ``__array__``)."""
        return np.asarray(self).astype(dtype, copy=copy)


@dataclass
class StoredTerrain(HeightField):
    """A HeightField over a tile store: ``heights`` is a LazyGrid of level 0; ``store`` is the opened group;
    ``source_step`` is the store's recorded step (None for a store without one)."""

    heights: Any  # a LazyGrid of level 0 (read by index; numpy where a HeightField needs an array)
    store: Any = None  # the opened zarr group (typed Any: its attrs and arrays are read untyped)
    path: str = ""

    def __post_init__(self):
        self.spacing_x, self.spacing_y = spacing_pair(self.spacing, self.name)
        self.spacing = self.spacing_x if self.spacing_x == self.spacing_y else (self.spacing_x, self.spacing_y)
        x, y, z = (float(v) for v in self.origin)
        self.origin = (x, y, z)

    @property
    def height_range(self) -> tuple[float, float]:
        """Minimum and maximum height in metres (relative to origin z), from the store's header."""
        return self.heights.range

    def window_extremes(self, r0, r1, c0, c1) -> tuple[np.ndarray, np.ndarray]:
        """Bounds (metres, relative to origin z) of the samples in each window rows r0..r1, cols c0..c1 (inclusive,
        arrays): the min of zmin and max of zmax over the tiles of a level whose tiles are at least a quarter of
        the window, so a few tiles answer each window."""
        r0, r1, c0, c1 = (np.asarray(a, dtype=np.int64) for a in (r0, r1, c0, c1))
        n, top = int(self.store.attrs["tile_size"]), int(self.store.attrs["max_level"])
        span = int(max(np.max(r1 - r0, initial=1), np.max(c1 - c0, initial=1)))
        level = min(top, max(0, int(np.ceil(np.log2(max(span / 4 / n, 1))))))
        cells = n << level
        zmin, zmax = np.asarray(self.store[f"zmin/{level}"][:]), np.asarray(self.store[f"zmax/{level}"][:])
        lo, hi = np.empty(len(r0)), np.empty(len(r0))
        for k in range(len(r0)):
            rows = slice(int(r0[k]) // cells, min(int(r1[k]) // cells, zmin.shape[0] - 1) + 1)
            cols = slice(int(c0[k]) // cells, min(int(c1[k]) // cells, zmin.shape[1] - 1) + 1)
            lo[k], hi[k] = zmin[rows, cols].min(), zmax[rows, cols].max()
        return lo, hi

    def load(self) -> HeightField:
        """The whole grid as an in-memory HeightField (refused beyond MAX_LOAD_SAMPLES)."""
        return HeightField(
            np.asarray(self.heights),
            (self.spacing_x, self.spacing_y),
            self.origin,
            self.name,
            None,
            source=self.path,
            notes=list(self.notes),
            source_step=self.source_step,
        )


HEADER_KEYS = ("version", "complete", "name", "spacing", "origin", "height_range", "tile_size", "max_level")


def store_remains(path) -> bool:
    """True if path is a directory that looks like a tile store (its header, manifest or levels), damaged or not."""
    p = Path(path)
    return p.is_dir() and any((p / name).exists() for name in ("zarr.json", MANIFEST, "levels"))


def _header(p: Path, path) -> dict:
    """The store's header (its group attributes), read from zarr.json after finishing or dropping an interrupted
    edit's write-through (``store_journal.recover``); a missing or garbled one refused by name."""
    import json

    if p.is_dir():
        recover(p)
    try:
        text = (p / "zarr.json").read_bytes()
    except OSError:
        if store_remains(p):
            raise damaged(path, "zarr.json", "is missing") from None
        raise TerrabenchError(f"{path}: not a terrabench tile store (make one with terrabench prepare)") from None
    try:
        attrs = json.loads(text).get("attributes", {})
    except (ValueError, AttributeError):
        raise damaged(path, "zarr.json", "is not valid JSON") from None
    if not isinstance(attrs, dict) or attrs.get("format") != STORE_FORMAT:
        raise TerrabenchError(f"{path}: not a terrabench tile store (make one with terrabench prepare)")
    missing = [k for k in HEADER_KEYS if k not in attrs]
    if missing:
        raise damaged(path, "zarr.json", f"lacks the header's {', '.join(missing)}")
    return attrs


def open_store(path) -> StoredTerrain:
    """Open a complete tile store (checked: format, version, completeness, every array's metadata against the
    manifest); every later read of a file the manifest lists is checked (``store_manifest``); refused by name."""
    p = Path(path)
    a = _header(p, path)
    if a.get("version") != STORE_VERSION:
        raise TerrabenchError(f"{path}: tile store version {a.get('version')!r}, this terrabench reads {STORE_VERSION}")
    if not a.get("complete"):
        raise TerrabenchError(
            f"{path}: tile store is incomplete (interrupted prepare); run the same prepare command again to finish it"
        )
    files = load_manifest(path, a)
    bad = bad_files(p, files, only_metadata=True) if files else []
    if bad:
        more = (
            f" (and {len(bad) - 1} more damaged files: terrabench info {path} --verify lists them)" if bad[1:] else ""
        )
        raise damaged(path, bad[0][0], bad[0][1] + more)
    zarr = _zarr()
    g = zarr.open_group(store=checked_store(path, files), mode="r")
    try:
        level0 = g["levels/0"]
    except KeyError:  # a store without a manifest: checked here, by name
        raise damaged(path, "levels/0/zarr.json", "is missing") from None
    except ValueError as exc:
        raise damaged(path, "levels/0/zarr.json", f"is not valid array metadata ({exc})") from None
    notes = [f"tile store {p.name}: {a.get('made_by', '')}"] + (["periodic extension"] if a.get("periodic") else [])
    step = a.get("source_step")
    return StoredTerrain(
        LazyGrid(level0, tuple(a["height_range"]), a["name"]),
        tuple(a["spacing"]),
        tuple(a["origin"]),
        a["name"],
        None,
        source=str(p),
        notes=notes,
        source_step=None if step is None else (float(step[0]), float(step[1])),
        store=g,
        path=str(p),
    )
