"""Height-field files: anything GDAL reads (through rasterio), 16-bit PNG, .npy/.npz and raw grids.

GeoTIFF/COG, SRTM .hgt, Esri .asc, .vrt and the other GDAL formats go through hybrid.terrain.gdal_files,
which takes CRS, transform, no-data and masks from the file. Image-like files (GDAL formats, PNG, raw) are
north-up: their first stored row is the north edge, and they are flipped on reading so that row 0 is the
south edge (see hybrid.terrain.heightfield). ``.npy``/``.npz`` arrays are taken as already south-up (what
``save_npz`` writes). No-data is filled by hybrid.terrain.voids, counted in ``HeightField.nodata_filled``,
and reported in a NoDataWarning and a note.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hybrid.errors import TerrainLoadError
from hybrid.terrain.assemble import NoDataWarning, assemble
from hybrid.terrain.heightfield import HeightField
from hybrid.terrain.window import Crop

__all__ = ["NoDataWarning", "load_npy", "load_png16", "load_raw", "load_terrain", "load_texture", "save_npz"]

GDAL_SUFFIXES = (".tif", ".tiff", ".hgt", ".asc", ".vrt", ".img", ".bil", ".dem")
SUFFIXES = {
    ".png": "png",
    ".npy": "npy",
    ".npz": "npz",
    ".raw": "raw",
    ".bin": "raw",
    ".r16": "raw",
    ".r32": "raw",
    **dict.fromkeys(GDAL_SUFFIXES, "gdal"),
}


def _need(path, what, value):
    if value is None:
        raise TerrainLoadError(f"{path}: the file does not give the {what}; pass it (--{what.replace(' ', '-')})")
    return value


def _cropped(path, arr: np.ndarray, crop: Crop | None, notes: list) -> np.ndarray:
    """The crop window of an array in file order (the whole array without one)."""
    if crop is None:
        return arr
    crop.check(arr.shape[:2], path)
    notes.append(f"window {crop.describe()} of {arr.shape[0]}x{arr.shape[1]}")
    return arr[crop.slices()]


def load_png16(
    path, *, vertical_scale=None, spacing=None, crop: Crop | None = None, texture_path=None, name=None
) -> HeightField:
    """Load a 16-bit (or 8-bit) greyscale PNG; height = value * vertical_scale metres, north-up file."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            arr = np.array(im)
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise TerrainLoadError(f"{path}: not a readable PNG ({exc})") from None
    if arr.ndim == 3:
        raise TerrainLoadError(f"{path}: a height map must have one channel, the file has {arr.shape[2]}")
    tex = None
    if texture_path is not None:
        tex = load_texture(texture_path, (arr.shape[0] - 1, arr.shape[1] - 1))
    notes: list[str] = []
    arr = _cropped(path, arr, crop, notes)
    if tex is not None and crop is not None:
        tex = tex[crop.row : crop.row + crop.rows - 1, crop.col : crop.col + crop.cols - 1]
    return assemble(
        path,
        arr,
        scale=float(_need(path, "vertical scale", vertical_scale)),
        spacing=_need(path, "spacing", spacing),
        texture=tex,
        name=name,
        notes=notes,
    )


def load_texture(path, cells_shape) -> np.ndarray:
    """Load an RGB texture (north-up, uint8) whose size must equal the height grid's cells (rows-1, cols-1)."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            tex = np.array(im.convert("RGB"))
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise TerrainLoadError(f"{path}: not a readable image ({exc})") from None
    if tex.shape[:2] != tuple(cells_shape):
        raise TerrainLoadError(
            f"{path}: texture is {tex.shape[1]}x{tex.shape[0]}, the height grid has "
            f"{cells_shape[1]}x{cells_shape[0]} cells (texels are cell-centred)"
        )
    return tex


def load_npy(path, *, vertical_scale=None, spacing=None, crop: Crop | None = None, name=None) -> HeightField:
    """Load .npy (a 2-D array) or .npz (key 'heights', else the only array; optional 'spacing': one number or
    (x, y) metres), south-up."""
    try:
        data = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise TerrainLoadError(f"{path}: not a readable NumPy file ({exc})") from None
    if isinstance(data, np.lib.npyio.NpzFile):
        with data:
            keys = list(data.keys())
            if "heights" in keys:
                arr = data["heights"]
            elif len(keys) == 1:
                arr = data[keys[0]]
            else:
                raise TerrainLoadError(f"{path}: .npz has arrays {keys}; name the heights 'heights'")
            if spacing is None and "spacing" in keys:
                stored = np.asarray(data["spacing"])
                if stored.shape not in ((), (1,), (2,)):
                    raise TerrainLoadError(
                        f"{path}: 'spacing' must hold one number or (x, y) metres, got shape {stored.shape}"
                    )
                spacing = float(stored.reshape(-1)[0]) if stored.size == 1 else tuple(float(v) for v in stored)
    else:
        arr = data
    notes: list[str] = []
    arr = _cropped(path, np.asarray(arr), crop, notes) if np.ndim(arr) == 2 else np.asarray(arr)
    return assemble(
        path,
        arr,
        scale=1.0 if vertical_scale is None else float(vertical_scale),
        spacing=_need(path, "spacing", spacing),
        north_up=False,
        name=name,
        notes=notes,
    )


def load_raw(
    path,
    *,
    shape,
    dtype,
    vertical_scale=1.0,
    spacing=None,
    crop: Crop | None = None,
    north_up=True,
    nodata=None,
    name=None,
) -> HeightField:
    """Load a headerless grid of the given (rows, cols) shape and NumPy dtype (e.g. '<u2', '<f4')."""
    try:
        dt = np.dtype(dtype)
    except TypeError:
        raise TerrainLoadError(f"{path}: unknown dtype {dtype!r}") from None
    rows, cols = (int(v) for v in shape)
    need = rows * cols * dt.itemsize
    size = os.path.getsize(path)
    if size != need:
        raise TerrainLoadError(f"{path}: {size} bytes, but shape {rows}x{cols} of {dt} needs {need}")
    notes: list[str] = []
    arr = _cropped(path, np.fromfile(path, dtype=dt).reshape(rows, cols), crop, notes)
    return assemble(
        path,
        arr,
        scale=float(vertical_scale),
        spacing=_need(path, "spacing", spacing),
        north_up=north_up,
        nodata=nodata,
        name=name,
        notes=notes,
    )


def load_terrain(path, **options) -> HeightField:
    """Load any supported height-field file, choosing the reader by suffix; options go to that reader.

    Options: ``spacing`` (metres, one number or (x, y)), ``vertical_scale`` (metres per stored unit),
    ``crop`` (a Crop window, rows as stored), ``crs`` (GDAL formats), ``shape``/``dtype`` (raw grids), ``name``.
    """
    from hybrid.terrain.gdal_files import load_gdal
    from hybrid.terrain.paths import path_problem

    p = Path(path)
    problem = path_problem(p)
    if problem is not None:
        raise TerrainLoadError(f"{path}: {problem}")
    if p.is_dir():
        raise TerrainLoadError(f"{path}: is a folder, not a height-field file")
    if p.stat().st_size == 0:
        raise TerrainLoadError(f"{path}: the file is empty")
    kind = SUFFIXES.get(p.suffix.lower())
    if kind is None:
        raise TerrainLoadError(f"{path}: unknown suffix {p.suffix!r}; supported: {', '.join(sorted(SUFFIXES))}")
    options = {k: v for k, v in options.items() if v is not None}
    readers: dict[str, Callable[..., HeightField]]
    readers = {"png": load_png16, "gdal": load_gdal, "npy": load_npy, "npz": load_npy, "raw": load_raw}
    reader = readers[kind]
    if kind == "raw" and ("shape" not in options or "dtype" not in options):
        raise TerrainLoadError(
            f"{path}: a raw grid needs an explicit shape (--raw-shape ROWSxCOLS) and dtype (--raw-dtype)"
        )
    if "crs" in options and kind != "gdal":
        raise TerrainLoadError(
            f"{path}: --crs applies to GDAL formats ({', '.join(GDAL_SUFFIXES)}), not {p.suffix}; "
            "give the ground spacing with --spacing"
        )
    try:
        return reader(str(p), **options)
    except TypeError as exc:
        raise TerrainLoadError(f"{path}: option not accepted by the {kind} reader ({exc})") from None


def save_npz(hf: HeightField, path) -> None:
    """Write heights (south-up, metres) and ground spacing (x, y metres) to an .npz that load_npy reads back."""
    np.savez(path, heights=hf.heights, spacing=np.array([hf.spacing_x, hf.spacing_y], dtype=np.float64))
