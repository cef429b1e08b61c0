"""The height field: real or synthetic terrain as a regular grid of heights in metres.

Conventions (the README states them once for the whole project):
- World frame: right-handed, x east, y north, z up, metres, float64 on the CPU.
- ``heights[i, j]``: row i counts from the SOUTH edge, column j from the WEST edge. Loaders flip
  north-up files (PNG, GeoTIFF, SRTM) on reading, so row order matches OpenGL textures (row 0 at t = 0).
- Sample (i, j) sits at world (origin_x + j*spacing_x, origin_y + i*spacing_y, origin_z + heights[i, j]):
  ground spacing may differ east-west (x) and north-south (y), as on geographic grids.
- Texel space of the height grid: sample (i, j) is texel coordinate (u, v) = (j, i); a cell (i, j) is
  the square between samples (i, j) and (i+1, j+1). Cell diagonal: from (i, j) to (i+1, j+1)
  (south-west to north-east) for every triangulated surface.
- The optional colour texture is cell-centred: texel (i, j) covers cell (i, j), so it has one row and
  one column fewer than the heights, and the same south-up row order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hybrid.errors import TerrabenchError

MAX_ABS_HEIGHT = 1.0e7  # metres: float32 heights keep steps of 1 m or finer within it; a numerical
# bound, not Earth's (exaggerated and extraterrestrial terrain stays allowed)
MAX_ORIGIN = 1.0e9  # metres: a terrain's world origin (as the camera's coordinates)


def spacing_pair(spacing, name: str = "terrain") -> tuple[float, float]:
    """The (x, y) ground spacing in metres from one number or a pair; refuses anything else by name."""
    try:
        pair = (spacing, spacing) if np.ndim(spacing) == 0 else tuple(spacing)
        sx, sy = (float(v) for v in pair)
    except (TypeError, ValueError):
        raise TerrabenchError(
            f"spacing of {name!r} must be a number or an (x, y) pair of metres, got {spacing!r}"
        ) from None
    for axis, v in (("x", sx), ("y", sy)):
        if not (np.isfinite(v) and v > 0):
            raise TerrabenchError(f"spacing {axis} of {name!r} must be finite and > 0 metres, got {v!r}")
    return sx, sy


@dataclass
class HeightField:
    """Heights in metres (float32, rows south to north), ground spacing, world origin, name and texture.

    ``spacing`` is one number (square cells) or a pair ``(spacing_x, spacing_y)`` in metres; after
    construction ``spacing_x``/``spacing_y`` hold the two, and ``spacing`` is the single number when they are
    equal and the pair otherwise. ``source_step`` is ``(step, offset)`` in metres when every height is
    float32(offset + step * k) for an integer k (set by the loaders of integer files; lets the ray caster
    store 16-bit heights exactly, hybrid.tiles.quantize), else None.
    """

    heights: np.ndarray
    spacing: float | tuple[float, float]
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    name: str = "terrain"
    texture: np.ndarray | None = None
    nodata_filled: int = 0
    source: str = ""
    notes: list[str] = field(default_factory=list)
    source_step: tuple[float, float] | None = None
    spacing_x: float = field(init=False, default=0.0)
    spacing_y: float = field(init=False, default=0.0)
    _range: tuple = field(init=False, default=(None, None), repr=False, compare=False)  # (heights array, its range)

    def __post_init__(self):
        h = np.asarray(self.heights)
        if h.ndim != 2:
            raise TerrabenchError(f"heights of {self.name!r} must be a 2-D array, got shape {h.shape}")
        if h.shape[0] < 2 or h.shape[1] < 2:
            raise TerrabenchError(f"heights of {self.name!r} need at least 2x2 samples, got {h.shape[0]}x{h.shape[1]}")
        if not np.issubdtype(h.dtype, np.number) or np.issubdtype(h.dtype, np.complexfloating):
            raise TerrabenchError(f"heights of {self.name!r} must be real numbers, got dtype {h.dtype}")
        if not np.all(np.isfinite(h)):
            bad = int(np.count_nonzero(~np.isfinite(h)))
            raise TerrabenchError(
                f"heights of {self.name!r} hold {bad} NaN/inf samples; load through hybrid.terrain.loaders "
                "(which fills no-data) or fill them first"
            )
        lo, hi = float(h.min()), float(h.max())  # checked before the float32 cast, which could overflow
        if max(-lo, hi) > MAX_ABS_HEIGHT:
            raise TerrabenchError(
                f"heights of {self.name!r} span {lo:g} .. {hi:g} m, beyond ±{MAX_ABS_HEIGHT:g} m, where float32 "
                "heights lose metre precision; check the vertical scale and units"
            )
        self.heights = np.ascontiguousarray(h.astype(np.float32, copy=False))
        self.spacing_x, self.spacing_y = spacing_pair(self.spacing, self.name)
        self.spacing = self.spacing_x if self.spacing_x == self.spacing_y else (self.spacing_x, self.spacing_y)
        o = tuple(float(v) for v in self.origin)
        if len(o) != 3 or not all(np.isfinite(o)):
            raise TerrabenchError(f"origin of {self.name!r} must be 3 finite numbers (x, y, z), got {self.origin!r}")
        if max(abs(v) for v in o) > MAX_ORIGIN:
            raise TerrabenchError(f"origin of {self.name!r} {o!r} lies beyond the world limit of ±{MAX_ORIGIN:g} m")
        self.origin = o
        if self.texture is not None:
            t = np.asarray(self.texture)
            want = (h.shape[0] - 1, h.shape[1] - 1)
            if t.ndim != 3 or t.shape[:2] != want or t.shape[2] not in (3, 4) or t.dtype != np.uint8:
                raise TerrabenchError(
                    f"texture of {self.name!r} must be uint8 of shape {want + (3,)} (cell-centred), "
                    f"got {t.dtype} {t.shape}"
                )
            self.texture = np.ascontiguousarray(t[..., :3])

    @property
    def rows(self) -> int:
        """Number of sample rows (south to north)."""
        return int(self.heights.shape[0])

    @property
    def cols(self) -> int:
        """Number of sample columns (west to east)."""
        return int(self.heights.shape[1])

    @property
    def extent(self) -> tuple[float, float]:
        """Width (x) and depth (y) of the terrain in metres."""
        return ((self.cols - 1) * self.spacing_x, (self.rows - 1) * self.spacing_y)

    @property
    def height_range(self) -> tuple[float, float]:
        """Minimum and maximum height in metres (relative to origin z); computed once per heights array (which,
        like the GPU copies made of it, is not changed in place), since renderers read it every frame."""
        array, value = self._range
        if array is not self.heights:
            value = (float(self.heights.min()), float(self.heights.max()))
            self._range = (self.heights, value)
        return value

    def heights_changed(self) -> None:
        """Say the heights were changed in place (an edit): their range is computed again when next read."""
        self._range = (None, None)

    def world_of(self, i, j) -> np.ndarray:
        """World position(s) (float64, metres) of sample(s) at row i, column j (may be fractional)."""
        i = np.asarray(i, dtype=np.float64)
        j = np.asarray(j, dtype=np.float64)
        x = self.origin[0] + j * self.spacing_x
        y = self.origin[1] + i * self.spacing_y
        z = self.origin[2] + self.sample_bilinear(i, j)
        return np.stack([x, y, z], axis=-1)

    def _cell(self, i, j):
        """Cell corner (i0, j0) and fractions (fi, fj) of fractional sample positions, clamped to the grid."""
        i = np.clip(np.asarray(i, dtype=np.float64), 0, self.rows - 1)
        j = np.clip(np.asarray(j, dtype=np.float64), 0, self.cols - 1)
        i0 = np.minimum(np.floor(i).astype(np.int64), self.rows - 2)
        j0 = np.minimum(np.floor(j).astype(np.int64), self.cols - 2)
        return i0, j0, i - i0, j - j0

    def sample_bilinear(self, i, j) -> np.ndarray:
        """Bilinearly interpolated height (metres, relative to origin z) at fractional row i, column j."""
        i0, j0, fi, fj = self._cell(i, j)
        h = self.heights
        a, b = h[i0, j0], h[i0, j0 + 1]
        c, d = h[i0 + 1, j0], h[i0 + 1, j0 + 1]
        return (a * (1 - fj) + b * fj) * (1 - fi) + (c * (1 - fj) + d * fj) * fi

    def sample_triangles(self, i, j) -> np.ndarray:
        """Height (metres, relative to origin z) of the triangulated surface (SW-NE diagonal) at row i, column j."""
        i0, j0, fi, fj = self._cell(i, j)
        h = self.heights
        h00, h01 = h[i0, j0].astype(np.float64), h[i0, j0 + 1]
        h10, h11 = h[i0 + 1, j0], h[i0 + 1, j0 + 1]
        lower = h00 + fj * (h01 - h00) + fi * (h11 - h01)
        upper = h00 + fi * (h10 - h00) + fj * (h11 - h10)
        return np.where(fj >= fi, lower, upper)

    def ground_height(self, x, y) -> np.ndarray:
        """World z (metres) of the drawn (triangulated) terrain below world (x, y), clamped to the edge."""
        j = (np.asarray(x, dtype=np.float64) - self.origin[0]) / self.spacing_x
        i = (np.asarray(y, dtype=np.float64) - self.origin[1]) / self.spacing_y
        return self.origin[2] + self.sample_triangles(i, j)

    def summary(self) -> str:
        """A few lines describing the height field, for `terrabench info`."""
        lo, hi = self.height_range
        w, d = self.extent
        lines = [
            f"name:        {self.name}",
            f"source:      {self.source or '(in memory)'}",
            f"samples:     {self.cols} x {self.rows} (columns x rows)",
            f"spacing:     {self.spacing_x:g} m east-west x {self.spacing_y:g} m north-south",
            f"extent:      {w / 1000:.2f} km x {d / 1000:.2f} km",
            f"heights:     {lo:.1f} .. {hi:.1f} m"
            + (f" (mean {float(self.heights.mean()):.1f} m)" if isinstance(self.heights, np.ndarray) else ""),
            f"origin:      ({self.origin[0]:g}, {self.origin[1]:g}, {self.origin[2]:g}) m",
            f"texture:     {f'{self.texture.shape[1]}x{self.texture.shape[0]} RGB' if self.texture is not None else 'none'}",
            f"no-data:     {self.nodata_filled} samples filled",
        ]
        lines += [f"note:        {n}" for n in self.notes]
        return "\n".join(lines)

    def moved(self, origin) -> HeightField:
        """The same terrain placed at another world origin (x, y, z) in metres."""
        return HeightField(
            self.heights,
            self.spacing,
            tuple(origin),
            self.name,
            self.texture,
            self.nodata_filled,
            self.source,
            list(self.notes),
            self.source_step,
        )
