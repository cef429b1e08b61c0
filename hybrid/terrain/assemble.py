"""From samples read off a file to a HeightField: checks, no-data found and filled, units, south-up rows."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from hybrid.errors import TerrabenchError, TerrainLoadError
from hybrid.terrain.heightfield import HeightField
from hybrid.terrain.voids import fill_voids


class NoDataWarning(UserWarning):
    """Some samples of a height field had no data and were filled."""


def check_grid(path, raw: np.ndarray) -> None:
    """Refuse anything but a 2-D grid of at least 2x2 real numbers, naming the file."""
    if raw.ndim != 2:
        raise TerrainLoadError(f"{path}: expected a 2-D grid of heights, got shape {raw.shape}")
    if raw.size == 0:
        raise TerrainLoadError(f"{path}: the file holds an empty grid")
    if raw.shape[0] < 2 or raw.shape[1] < 2:
        raise TerrainLoadError(f"{path}: a terrain needs at least 2x2 samples, got {raw.shape[0]}x{raw.shape[1]}")
    if not (np.issubdtype(raw.dtype, np.integer) or np.issubdtype(raw.dtype, np.floating)) or raw.dtype == np.bool_:
        raise TerrainLoadError(f"{path}: heights must be integers or floats, got dtype {raw.dtype}")


def assemble(
    path,
    raw: np.ndarray,
    *,
    spacing,
    scale: float = 1.0,
    offset: float = 0.0,
    nodata=None,
    missing: np.ndarray | None = None,
    north_up: bool = True,
    east_left: bool = True,
    name=None,
    texture=None,
    origin=(0.0, 0.0, 0.0),
    notes=(),
) -> HeightField:
    """A HeightField from a 2-D array in file order: height = stored value * scale + offset metres.

    No-data is the given value, NaN/inf and ``missing`` (True = no data); it is filled (hybrid.terrain.voids),
    counted in ``nodata_filled`` and reported in a NoDataWarning and a note. North-up rows are flipped to
    south-up; ``east_left=False`` (columns running east to west) flips the columns.
    """
    check_grid(path, raw)
    vals = raw.astype(np.float64)
    gone = ~np.isfinite(vals)
    if missing is not None:
        gone |= np.asarray(missing, dtype=bool)
    if nodata is not None and np.isfinite(nodata):
        gone |= vals == float(nodata)
    n_missing = int(gone.sum())
    if n_missing == vals.size:
        raise TerrainLoadError(f"{path}: all {vals.size} samples are no-data")
    notes = list(notes)
    if n_missing:
        vals, report = fill_voids(vals, gone, integer=bool(np.issubdtype(raw.dtype, np.integer)))
        text = report.describe(vals.size)
        notes.append(f"no-data: {text}")
        warnings.warn(f"{path}: {text}", NoDataWarning, stacklevel=3)
    heights = (vals * scale + offset).astype(np.float32)
    if north_up:
        heights = heights[::-1]
        texture = None if texture is None else texture[::-1]
    if not east_left:
        heights = heights[:, ::-1]
        texture = None if texture is None else texture[:, ::-1]
    try:
        step = (float(scale), float(offset)) if np.issubdtype(raw.dtype, np.integer) else None
        return HeightField(
            np.ascontiguousarray(heights),
            spacing,
            origin,
            name or Path(path).stem,
            None if texture is None else np.ascontiguousarray(texture),
            n_missing,
            str(path),
            notes,
            step,
        )
    except TerrabenchError as exc:
        raise TerrainLoadError(f"{path}: {exc}") from None
