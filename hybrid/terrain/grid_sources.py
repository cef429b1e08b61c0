"""Height grids read a band of rows at a time, for building tile stores out of core.

A grid source has ``rows``, ``cols``, ``spacing`` (metres, one number or (x, y)), ``name``, ``notes`` and
``read_rows(r0, r1)``: rows r0..r1-1 (south to north, as every terrabench grid) as float32 metres, and may have
``source_step`` ((step, offset) metres when every height is float32(offset + step * k), k an integer, as
``HeightField.source_step``; a tile store records it). Three kinds:
a GDAL file through rasterio (windows of the file, never the whole grid), a seeded fractal terrain whose
every sample is a function of its own position and the seed, so any window gives the same samples, and a
height field already in memory (a bundled dataset made into a store).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from hybrid.errors import TerrabenchError, TerrainLoadError


class GdalGridSource:
    """A GDAL-readable height grid (GeoTIFF/COG, .hgt, .asc, .vrt, ...) read in row bands through rasterio."""

    def __init__(self, path, *, vertical_scale=None, spacing=None, crs=None, crop=None, name=None):
        from rasterio.errors import NotGeoreferencedWarning

        from .gdal_files import _open, grid_header

        self.path = str(path)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            self.src = _open(self.path)
        self.h = grid_header(self.path, self.src, vertical_scale=vertical_scale, spacing=spacing, crs=crs, crop=crop)
        self.rows, self.cols = self.h.shape
        self.spacing = self.h.ground
        self.name = name or Path(self.path).stem
        self.notes = list(self.h.notes)
        self._row0 = 0 if self.h.window is None else int(self.h.window.row_off)
        self._col0 = 0 if self.h.window is None else int(self.h.window.col_off)
        integer = np.issubdtype(np.dtype(self.src.dtypes[self.h.band - 1]), np.integer)
        self.source_step = (float(self.h.scale), float(self.h.offset)) if integer else None  # as the loader's

    def read_rows(self, r0: int, r1: int) -> np.ndarray:
        """Rows r0..r1-1 counted from the south, (r1 - r0, cols) float32 metres; no-data is refused by name."""
        from rasterio.windows import Window

        f0 = self.rows - r1 if self.h.north_up else r0  # the band's first row in the file
        win = Window(self._col0, self._row0 + f0, self.cols, r1 - r0)
        try:
            raw = self.src.read(self.h.band, window=win)
            valid = self.src.read_masks(self.h.band, window=win)
        except Exception as exc:  # GDAL raises several types for truncated or corrupt data
            raise TerrainLoadError(f"{self.path}: GDAL cannot read rows {f0}..{f0 + r1 - r0} ({exc})") from None
        if not valid.all():
            raise TerrainLoadError(
                f"{self.path}: {int((valid == 0).sum())} no-data samples in rows {f0}..{f0 + r1 - r0}; a tile store "
                "is built a band at a time and does not fill voids: fill them first (e.g. gdal_fillnodata.py), or "
                "load the file whole, where terrabench fills them"
            )
        h = raw.astype(np.float64) * self.h.scale + self.h.offset
        if self.h.north_up:
            h = h[::-1]
        if not self.h.east_left:
            h = h[:, ::-1]
        if not np.all(np.isfinite(h)):
            raise TerrainLoadError(f"{self.path}: NaN/inf heights in rows {f0}..{f0 + r1 - r0}")
        return np.ascontiguousarray(h, dtype=np.float32)

    def close(self) -> None:
        """Close the file."""
        self.src.close()


def _hash(seed: int, octave: int, ix: np.ndarray, iy: np.ndarray) -> np.ndarray:
    """Uniform values in [-1, 1) from integer lattice points, the seed and the octave (a 64-bit mix)."""
    with np.errstate(over="ignore"):
        h = (ix.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)) ^ (
            iy.astype(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F)
        )
        h ^= np.uint64((seed * 1000003 + octave * 7919) & 0xFFFFFFFFFFFFFFFF)
        h ^= h >> np.uint64(33)
        h *= np.uint64(0xFF51AFD7ED558CCD)
        h ^= h >> np.uint64(33)
    return (h >> np.uint64(11)).astype(np.float64) / float(1 << 52) - 1.0


def _value_noise(seed: int, octave: int, y: np.ndarray, x: np.ndarray, wrap: int | None = None) -> np.ndarray:
    """Smooth value noise at lattice-unit coordinates (y rows, x columns broadcast together); with ``wrap`` the
    lattice repeats every ``wrap`` units (a seamless tile)."""
    iy, ix = np.floor(y).astype(np.int64), np.floor(x).astype(np.int64)
    fy, fx = y - iy, x - ix
    sy, sx = fy * fy * (3 - 2 * fy), fx * fx * (3 - 2 * fx)
    iy1, ix1 = iy + 1, ix + 1
    if wrap:
        iy, ix, iy1, ix1 = iy % wrap, ix % wrap, iy1 % wrap, ix1 % wrap
    a, b = _hash(seed, octave, ix, iy), _hash(seed, octave, ix1, iy)
    c, d = _hash(seed, octave, ix, iy1), _hash(seed, octave, ix1, iy1)
    return (a + (b - a) * sx) * (1 - sy) + (c + (d - c) * sx) * sy


class FractalSource:
    """A seeded fractal terrain of size x size samples: fBm valleys, ridged mountains and flat basins (metres).

    Every sample depends only on its (row, column) and the seed, so reading it in any windows gives the same
    bytes; ``relief`` is the height scale in metres, ``feature_cells`` the largest features' size in samples.
    With ``period`` (a power of two of at least 2 x feature_cells) the terrain repeats every ``period`` samples
    both ways, seamlessly: sample (i, j) equals (i mod period, j mod period), so a store of period + 1 samples
    extends periodically without a seam.
    """

    def __init__(
        self,
        size: int,
        seed: int = 0,
        spacing: float = 10.0,
        relief: float = 1500.0,
        feature_cells: int = 512,
        octaves: int = 10,
        period: int | None = None,
    ):
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or not 2 <= size <= 1_048_577:
            raise TerrabenchError(f"synthetic size must be an integer in [2, 1048577] samples, got {size!r}")
        if not (0 <= seed < 2**32):
            raise TerrabenchError(f"seed must lie in [0, 2^32), got {seed!r}")
        self.rows = self.cols = int(size)
        self.seed, self.spacing, self.relief = int(seed), float(spacing), float(relief)
        self.feature, self.octaves = float(feature_cells), int(octaves)
        if period is not None and (
            isinstance(period, bool) or int(period) != period or period & (period - 1) or period < 2 * feature_cells
        ):
            raise TerrabenchError(
                f"period must be a power of two of at least {2 * feature_cells} samples, got {period!r}"
            )
        self.period = None if period is None else int(period)
        self.name = f"fractal-{size}-s{seed}" + (f"-p{period}" if period else "")
        self.notes = [f"synthetic: fBm, ridges and flat basins, seed {seed}, {spacing:g} m spacing"]

    def read_rows(self, r0: int, r1: int) -> np.ndarray:
        """Rows r0..r1-1 (south to north) as float32 metres."""
        y = np.arange(r0, r1, dtype=np.float64)[:, None]
        x = np.arange(self.cols, dtype=np.float64)[None, :]
        base = np.zeros((r1 - r0, self.cols))
        ridge = np.zeros_like(base)
        amp, cell = 1.0, self.feature

        def wrap(c):
            return int(self.period // c) if self.period else None

        for o in range(self.octaves):
            n = _value_noise(self.seed, o, y / cell, x / cell, wrap(cell))
            base += amp * n
            if o < 6:
                ridge += amp * (1.0 - np.abs(_value_noise(self.seed + 1, o, y / cell, x / cell, wrap(cell))))
            amp *= 0.5
            cell = max(cell / 2.0, 1.0)
        big = 2 * self.feature
        mask = np.clip(0.5 + 1.5 * _value_noise(self.seed + 2, 0, y / big, x / big, wrap(big)), 0, 1)
        h = self.relief * (0.35 * base + 0.65 * mask * ridge**2)
        level = 0.7 * self.relief
        h = np.where(h < level, level + 0.05 * (h - level), h)  # flat basins below the level
        return h.astype(np.float32)


class HeightFieldSource:
    """A height field held in memory (e.g. the bundled Puget model) read as a grid source, for a store of it."""

    def __init__(self, hf):
        self.hf, self.rows, self.cols = hf, hf.rows, hf.cols
        self.spacing, self.name = (hf.spacing_x, hf.spacing_y), hf.name
        self.notes, self.source_step = list(hf.notes), hf.source_step

    def read_rows(self, r0: int, r1: int) -> np.ndarray:
        """Rows r0..r1-1 (south to north) as float32 metres."""
        return np.ascontiguousarray(self.hf.heights[r0:r1], dtype=np.float32)
