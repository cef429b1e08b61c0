"""The tile pyramid: square tiles of N cells (N+1 samples, borders shared) at every level of detail.

Level 0 is the full-resolution grid; level l keeps every 2^l-th sample of level 0 (subsampling, as
Bhattacharjee et al.), not 2x2 averages (Dick et al.). We subsample because then every coarse sample is a
real level-0 sample: tile borders of all levels lie exactly on the level-0 surface, the geometric error
below is a plain maximum deviation from measured heights, and a coarse tile never lifts or sinks the
terrain as averaging does at peaks and cliffs (a summit keeps its height until its sample is dropped).

Tiles are addressed as in a square of N*2^L + 1 samples a side, the grid repeated at its edges, but only
the tiles over the grid's own rectangle exist, and that square is never built: a tile's samples are gathered
with clamped indices, and every per-level array covers the rectangle only, so memory follows the data (a
2 x 20000 grid costs what its samples do, not a 20000² square). The padding is never drawn: each tile
carries ``clip`` (the world rectangle of real terrain it covers) and renderers clip to it. A tile's AABB
spans the level-0 heights over its clipped region, so it bounds the surface of every level; ``error`` is the largest vertical distance (metres) between the tile's
triangulated level-l surface and the level-0 samples it covers, made monotone (a parent's error is at
least its children's).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.edits import Window
from hybrid.terrain.heightfield import HeightField
from hybrid.tiles import pyramid_edit as pedit
from hybrid.tiles.bounds import level_bounds, strided_samples
from hybrid.tiles.quantize import Q_MAX, error_bound, on_step_cells
from hybrid.tiles.subsampling import block_reduce

EDGE_W, EDGE_E, EDGE_S, EDGE_N = 1, 2, 4, 8


class TileKey(NamedTuple):
    """A tile's address: pyramid level (0 = finest) and column tx / row ty among that level's tiles.

    A named tuple: hashed and compared in C, as the keys of every per-tile cache are, many times a frame."""

    level: int
    tx: int
    ty: int

    def children(self) -> tuple[TileKey, ...]:
        """The four tiles of the next finer level covering this one (SW, SE, NW, NE)."""
        l, x, y = self.level - 1, 2 * self.tx, 2 * self.ty
        return (TileKey(l, x, y), TileKey(l, x + 1, y), TileKey(l, x, y + 1), TileKey(l, x + 1, y + 1))

    def parent(self) -> TileKey:
        """The tile of the next coarser level that contains this one."""
        return TileKey(self.level + 1, self.tx // 2, self.ty // 2)


@dataclass(frozen=True)
class Tile:
    """What a renderer needs of one tile: its level-l samples and where they sit in the world.

    heights: (N+1, N+1) float32 metres relative to the terrain's origin z, rows south to north.
    origin: world (x, y, z) of sample [0, 0] (z is the terrain's origin z), float64 metres.
    spacing_x, spacing_y: metres between this tile's samples east-west and north-south (the terrain's
      spacing_x, spacing_y times 2^level).
    clip: world rectangle (x0, y0, x1, y1) of real terrain inside the tile; never draw outside it.
    zmin, zmax: world heights bounding the tile's surface at every level.
    error: geometric error in metres of this tile's level against level 0.
    source_step: the terrain's (step, offset) in metres when its heights lie on an integer step (HeightField),
      else None; the ray caster's 16-bit heights are exact there (hybrid.tiles.quantize).
    host: what a store's loader thread made of these heights for a strategy's upload, by product name (taken by
      the upload that uses it: ``StorePyramid.derive``).
    """

    key: TileKey
    heights: np.ndarray
    origin: tuple[float, float, float]
    spacing_x: float
    spacing_y: float
    clip: tuple[float, float, float, float]
    zmin: float
    zmax: float
    error: float
    source_step: tuple[float, float] | None = None
    host: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def n(self) -> int:
        """Cells per side."""
        return self.heights.shape[0] - 1

    @property
    def spacing_xy(self) -> tuple[float, float]:
        """(spacing_x, spacing_y): metres between the tile's samples east-west and north-south."""
        return (self.spacing_x, self.spacing_y)

    @property
    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space (min corner, max corner) of the tile's clipped bounding box, float64."""
        x0, y0, x1, y1 = self.clip
        return np.array([x0, y0, self.zmin]), np.array([x1, y1, self.zmax])

    @property
    def nbytes_heights(self) -> int:
        """Bytes of the tile's heights as float32."""
        return int(self.heights.size * 4)


MAX_PADDED_SAMPLES = 1 << 27  # the square only the reference node arrays build (raster.nodes.square_nodes): 128 M


class TilePyramid:
    """Tiles of ``tile_size`` cells over a height field at levels 0..max_level, with AABBs and errors.

    Host loading: an in-memory pyramid holds every sample, so ``request``, ``cached``, ``failed`` and ``close`` do
    nothing here; a tile store (``hybrid.tiles.store.StorePyramid``) sets ``background_loader`` and overrides them.
    """

    background_loader = False
    """Whether a loader thread reads tiles ahead (``request``); callers then ask ``cached`` and ``failed``."""
    host_budget: int | None = None
    """Bytes of tiles the pyramid keeps on the host, or None: all of them (in memory)."""
    edits = 0
    """How many times its bounds changed after an edit; caches made from them elsewhere compare it."""
    _dev_blocks: pedit.DeviationBlocks | None = None  # made at the first edit (hybrid.tiles.pyramid_edit)

    def __init__(self, hf: HeightField, tile_size: int = 256):
        if (
            isinstance(tile_size, bool)
            or not isinstance(tile_size, (int, np.integer))
            or tile_size < 2
            or tile_size & (tile_size - 1)
        ):
            raise TerrabenchError(f"tile size must be a power of two >= 2 cells, got {tile_size!r}")
        self.hf = hf
        self.n = int(tile_size)
        cells = max(hf.rows, hf.cols) - 1
        tiles0 = -(-cells // self.n)
        self.max_level = int(np.ceil(np.log2(tiles0))) if tiles0 > 1 else 0
        self.size = self.n * (1 << self.max_level) + 1  # samples a side of the addressing square
        self._new_caches()
        self._on_step: np.ndarray | None = None  # per cell: corners on the source step (hybrid.tiles.quantize)
        self._build_bounds()

    def _new_caches(self) -> None:
        """Empty the per-level arrays made on first use (every pyramid's constructor calls this)."""
        self._boxes: dict = {}  # level -> boxes_at's arrays of every tile
        self._qerr: dict = {}  # level -> quantisation error bounds
        self._on_tiles: dict = {}  # level -> per tile: every cell it covers on the source step
        self._tables: dict = {}  # level -> level_table

    @property
    def padded(self) -> np.ndarray:
        """The addressing square itself (size² float32, edge-repeated), built on demand for consumers that need
        a square grid; refused by name when it would exceed MAX_PADDED_SAMPLES."""
        need = self.size * self.size
        if need > MAX_PADDED_SAMPLES:
            raise TerrabenchError(
                f"{self.hf.name!r} ({self.hf.cols}x{self.hf.rows} samples, tiles of {self.n}) would need a padded "
                f"square of {self.size}² samples ({need * 4 / 2**30:.1f} GiB as float32, several times that to process), "
                f"beyond the limit of {MAX_PADDED_SAMPLES} samples; the strategies do not need it (raster node arrays "
                "are computed over the grid's rectangle, raster.rect_nodes)"
            )
        hf = self.hf
        return np.pad(hf.heights, ((0, self.size - hf.rows), (0, self.size - hf.cols)), mode="edge")

    # --- per-level arrays -------------------------------------------------------------------------
    def tiles_per_side(self, level: int) -> int:
        """Number of tile columns (= rows) of the addressing square at a level; only those over the grid exist."""
        return 1 << (self.max_level - level)

    def tile_counts(self, level: int) -> tuple[int, int]:
        """(rows, columns) of the level's existing tiles: those over the grid's own rectangle."""
        return self._zmax[level].shape

    def _build_bounds(self):
        """Per level: the tiles' height bounds and geometric errors (hybrid.tiles.bounds, block by block).

        A level-0 cell's min/max over its four corners bounds every reconstruction of the cell; a level's
        error is each tile's largest deviation of its triangulated surface from level 0, made monotone."""
        self._zmax, self._zmin, self._err = level_bounds(self.hf.heights, self.n, self.max_level)

    def level_arrays(self, level: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(zmin, zmax, error) per tile of a level: (rows, cols) float32 metres, read-only views."""
        out = tuple(a[level].view() for a in (self._zmin, self._zmax, self._err))
        for a in out:
            a.flags.writeable = False
        return out[0], out[1], out[2]

    # --- edits ------------------------------------------------------------------------------------
    def touched_keys(self, win: Window) -> list[TileKey]:
        """Every existing tile of every level whose samples meet a window of level-0 samples, finest level first."""
        touched = [pedit.touched_tiles(self, win, level) for level in range(self.max_level + 1)]
        return [TileKey(level, tx, ty) for level, (rows, cols) in enumerate(touched) for ty in rows for tx in cols]

    def follow_edit(self, win: Window) -> list[TileKey]:
        """Bring bounds, errors and caches of the touched tiles up to date after the samples of ``win`` changed in
        place in the height field (equal to a rebuild); returns those tiles (``touched_keys``)."""
        if win.empty:
            return []
        self.hf.heights_changed()
        if self._dev_blocks is None:
            self._dev_blocks = pedit.level_blocks(self.hf.heights, self.max_level, self.n)
        arrays = pedit.LevelArrays(self._zmax, self._zmin, self._err)
        caches = {"qerr": self._qerr, "boxes": self._boxes, "tables": self._tables, "on_step": self._on_step}
        caches["on_tiles"] = self._on_tiles
        pedit.follow_levels(self, arrays, caches, self._dev_blocks, win)
        self.edits += 1
        return self.touched_keys(win)

    # --- tiles ------------------------------------------------------------------------------------
    def exists(self, key: TileKey) -> bool:
        """True if the tile covers any real (unpadded) terrain."""
        if not (0 <= key.level <= self.max_level):
            return False
        ty, tx = self.tile_counts(key.level)
        return 0 <= key.tx < tx and 0 <= key.ty < ty

    def root(self) -> TileKey:
        """The single tile of the coarsest level."""
        return TileKey(self.max_level, 0, 0)

    def keys(self, level: int) -> list[TileKey]:
        """All existing tiles of a level, row by row from the south."""
        ty, tx = self.tile_counts(level)
        return [TileKey(level, x, y) for y in range(ty) for x in range(tx)]

    def exists_at(self, level: int, tx: np.ndarray, ty: np.ndarray) -> np.ndarray:
        """Boolean array: which of the level's tiles (tx, ty), given as integer arrays, exist."""
        rows, cols = self.tile_counts(level)
        tx, ty = np.asarray(tx, dtype=np.int64), np.asarray(ty, dtype=np.int64)
        return (tx >= 0) & (tx < cols) & (ty >= 0) & (ty < rows)

    def boxes_at(self, level: int, tx: np.ndarray, ty: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World-space (min, max) corners, (B, 3) float64 metres, of the level's existing tiles (tx, ty)."""
        if level not in self._boxes:  # every box of a level, made on first use
            rows, cols = self.tile_counts(level)
            ty_all, tx_all = np.divmod(np.arange(rows * cols), cols)
            self._boxes[level] = tuple(
                a.reshape(rows, cols, 3) for a in self.aabbs(np.full(rows * cols, level), tx_all, ty_all)
            )
        lo, hi = self._boxes[level]
        return lo[ty, tx], hi[ty, tx]

    def level_table(self, level: int) -> np.ndarray:
        """(rows, cols, 7) float64 per tile of a level: its box's world min and max corners (metres) and the error
        tile selection refines by (geometric plus the 16-bit quantisation bound, metres); made on first use."""
        if level not in self._tables:
            rows, cols = self.tile_counts(level)
            ty, tx = np.divmod(np.arange(rows * cols), cols)
            lo, hi = self.boxes_at(level, tx, ty)
            err = self.errors_at(level, tx, ty) + self.quantization_errors_at(level, tx, ty)
            self._tables[level] = np.concatenate([lo, hi, err[:, None]], axis=1).reshape(rows, cols, 7)
        return self._tables[level]

    def errors_at(self, level: int, tx: np.ndarray, ty: np.ndarray) -> np.ndarray:
        """Geometric errors (metres, float64) of the level's existing tiles (tx, ty), given as integer arrays."""
        return self._err[level][np.asarray(ty, dtype=np.int64), np.asarray(tx, dtype=np.int64)].astype(np.float64)

    def quantization_errors_at(self, level: int, tx: np.ndarray, ty: np.ndarray) -> np.ndarray:
        """Bounds (metres, float64) on the 16-bit quantisation error of the level's tiles (tx, ty)
        (hybrid.tiles.quantize): 0 where the tile's heights are on the terrain's source step, else
        range / 131070 plus float32 rounding; tile selection adds them to the geometric errors."""
        if level not in self._qerr:
            lo, hi = self._zmin[level], self._zmax[level]
            exact = False
            step = getattr(self.hf, "source_step", None)
            if step is not None and isinstance(self.hf, HeightField):
                on = self._on_step_tiles(level, step)
                exact = on & ((hi.astype(np.float64) - lo) / float(step[0]) <= Q_MAX - 0.5)
            self._qerr[level] = error_bound(lo, hi, exact)
        return self._qerr[level][np.asarray(ty, dtype=np.int64), np.asarray(tx, dtype=np.int64)]

    def _on_step_tiles(self, level: int, step) -> np.ndarray:
        """Per tile of a level: True where every level-0 sample it covers is on the source step (made once a level,
        followed by edits)."""
        if self._on_step is None:
            self._on_step = on_step_cells(self.hf.heights, step)
        assert self._on_step is not None, "on-step tiles asked of a grid without a source step"
        if level not in self._on_tiles:
            self._on_tiles[level] = block_reduce(self._on_step, self.n << level, np.minimum)
        return self._on_tiles[level]

    def quantization_error(self, key: TileKey) -> float:
        """Bound (metres) on the tile's 16-bit quantisation error, as quantization_errors_at."""
        return float(self.quantization_errors_at(key.level, np.array([key.tx]), np.array([key.ty]))[0])

    def error(self, key: TileKey) -> float:
        """Geometric error (metres) of the tile's level-l surface against level 0."""
        return float(self._err[key.level][key.ty, key.tx])

    def zrange(self, key: TileKey) -> tuple[float, float]:
        """World z range (min, max) in metres bounding the tile's surface."""
        oz = self.hf.origin[2]
        return oz + float(self._zmin[key.level][key.ty, key.tx]), oz + float(self._zmax[key.level][key.ty, key.tx])

    def clip(self, key: TileKey) -> tuple[float, float, float, float]:
        """World rectangle (x0, y0, x1, y1) of real terrain inside the tile."""
        hf = self.hf
        cells = self.n << key.level
        span_x, span_y = cells * hf.spacing_x, cells * hf.spacing_y
        ox, oy = hf.origin[0], hf.origin[1]
        x0, y0 = ox + key.tx * span_x, oy + key.ty * span_y
        x1 = min(x0 + span_x, ox + (hf.cols - 1) * hf.spacing_x)
        y1 = min(y0 + span_y, oy + (hf.rows - 1) * hf.spacing_y)
        return (x0, y0, x1, y1)

    def aabb(self, key: TileKey) -> tuple[np.ndarray, np.ndarray]:
        """World-space (min, max) corners of the tile's bounding box."""
        x0, y0, x1, y1 = self.clip(key)
        z0, z1 = self.zrange(key)
        return np.array([x0, y0, z0]), np.array([x1, y1, z1])

    def aabbs(self, levels: np.ndarray, tx: np.ndarray, ty: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World-space (min, max) corners, (B, 3) float64 metres each, of tiles given as arrays of level, tx, ty.

        The same values as ``aabb`` of each key, computed per level with array indexing.
        """
        levels, tx, ty = (np.asarray(a, dtype=np.int64).reshape(-1) for a in (levels, tx, ty))
        hf = self.hf
        ox, oy, oz = hf.origin
        cells = self.n << levels
        span_x, span_y = cells * hf.spacing_x, cells * hf.spacing_y
        x0, y0 = ox + tx * span_x, oy + ty * span_y
        x1 = np.minimum(x0 + span_x, ox + (hf.cols - 1) * hf.spacing_x)
        y1 = np.minimum(y0 + span_y, oy + (hf.rows - 1) * hf.spacing_y)
        z0, z1 = np.empty(len(levels)), np.empty(len(levels))
        for level in np.unique(levels):
            at = levels == level
            z0[at] = oz + self._zmin[int(level)][ty[at], tx[at]].astype(np.float64)
            z1[at] = oz + self._zmax[int(level)][ty[at], tx[at]].astype(np.float64)
        lo, hi = np.empty((len(levels), 3)), np.empty((len(levels), 3))
        lo[:, 0], lo[:, 1], lo[:, 2], hi[:, 0], hi[:, 1], hi[:, 2] = x0, y0, z0, x1, y1, z1
        return lo, hi

    def request(self, keys, work: dict | None = None) -> threading.Event | None:
        """Have these tiles (and their host ``work``) ready soon: in memory they are (None: nothing to wait for)."""
        return None

    def cached(self, key) -> bool:
        """Whether the tile's samples are on the host: always, in memory."""
        return True

    def failed(self, key) -> bool:
        """Whether loading the tile failed: never, in memory."""
        return False

    def close(self) -> None:
        """Stop background loading and drop host caches: nothing to do in memory."""

    def tile(self, key: TileKey) -> Tile:
        """The tile's level-l samples and placement."""
        if not self.exists(key):
            raise TerrabenchError(
                f"tile {key} does not exist (levels 0..{self.max_level}, "
                f"{self.tiles_per_side(key.level) if 0 <= key.level <= self.max_level else 0} tiles a side)"
            )
        h = self.samples(key)
        origin, (sx, sy) = self.placement(key)
        z0, z1 = self.zrange(key)
        return Tile(
            key,
            np.ascontiguousarray(h, dtype=np.float32),
            origin,
            sx,
            sy,
            self.clip(key),
            z0,
            z1,
            self.error(key),
            getattr(self.hf, "source_step", None),
            self.host_products(key),
        )

    def host_products(self, key: TileKey) -> dict:
        """What a loader thread made of the tile's heights for uploads, handed over once: none in memory."""
        return {}

    def placement(self, key: TileKey) -> tuple[tuple[float, float, float], tuple[float, float]]:
        """(world origin of the tile's sample [0, 0], (spacing_x, spacing_y)) in metres, without its samples."""
        k = 1 << key.level
        i0, j0 = key.ty * self.n * k, key.tx * self.n * k
        hf = self.hf
        return (
            (hf.origin[0] + j0 * hf.spacing_x, hf.origin[1] + i0 * hf.spacing_y, hf.origin[2]),
            (hf.spacing_x * k, hf.spacing_y * k),
        )

    def samples(self, key: TileKey) -> np.ndarray:
        """The tile's (N+1)² level-l samples (metres, rows south to north), gathered with clamped indices."""
        k = 1 << key.level
        return strided_samples(self.hf.heights, key.ty * self.n * k, key.tx * self.n * k, k, self.n + 1)

    def texture_rect(self, key: TileKey) -> tuple[int, int, int, int]:
        """Cell (texel) index range (j0, i0, j1, i1) of the terrain's texture that the tile covers."""
        k = self.n << key.level
        hf = self.hf
        return (key.tx * k, key.ty * k, min((key.tx + 1) * k, hf.cols - 1), min((key.ty + 1) * k, hf.rows - 1))
