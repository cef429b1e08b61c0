"""Height-field loaders: 16-bit PNG, GeoTIFF, .npy/.npz, SRTM .hgt and raw grids, with no-data filling.

Image-like files (PNG, GeoTIFF, HGT, raw) are north-up: their first row is the north edge. They are
flipped on reading so that row 0 is the south edge (see hybrid.terrain.heightfield). ``.npy``/``.npz`` arrays are
taken as already in the project's south-up order (what ``save_npz`` writes).

No-data (the file's GDAL no-data tag, SRTM's -32768, NaN/inf, or a value given by the caller) is filled
by iterated neighbour averaging: each pass gives every missing sample that touches known samples the
mean of its known 4-neighbours, until none is missing. The count goes into ``HeightField.nodata_filled``
and a warning names the file.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from hybrid.errors import TerrabenchError, TerrainLoadError
from hybrid.terrain.heightfield import HeightField

SRTM_NODATA = -32768
SUFFIXES = {".png": "png", ".tif": "tiff", ".tiff": "tiff", ".npy": "npy", ".npz": "npz", ".hgt": "hgt",
            ".raw": "raw", ".bin": "raw", ".r16": "raw", ".r32": "raw"}


class NoDataWarning(UserWarning):
    """Some samples of a height field had no data and were filled."""


def fill_nodata(values: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """Fill samples where ``missing`` is True by iterated 4-neighbour averaging of known samples (float64)."""
    h = np.where(missing, 0.0, values).astype(np.float64)
    known = ~missing
    if not known.any():
        raise TerrabenchError("every sample is no-data: nothing to fill from")
    while not known.all():
        s = np.zeros_like(h)
        n = np.zeros(h.shape, dtype=np.int32)
        kh = np.where(known, h, 0.0)
        ki = known.astype(np.int32)
        s[1:, :] += kh[:-1, :]; n[1:, :] += ki[:-1, :]
        s[:-1, :] += kh[1:, :]; n[:-1, :] += ki[1:, :]
        s[:, 1:] += kh[:, :-1]; n[:, 1:] += ki[:, :-1]
        s[:, :-1] += kh[:, 1:]; n[:, :-1] += ki[:, 1:]
        grow = (~known) & (n > 0)
        h[grow] = s[grow] / n[grow]
        known = known | grow
    return h


def _finish(path: str, raw: np.ndarray, *, scale: float, spacing, nodata=None, north_up=True,
            name=None, texture=None, origin=(0.0, 0.0, 0.0), notes=()) -> HeightField:
    """Turn a raw 2-D array into a HeightField: check, find and fill no-data, scale, flip to south-up."""
    if raw.ndim != 2:
        raise TerrainLoadError(f"{path}: expected a 2-D grid of heights, got shape {raw.shape}")
    if raw.size == 0:
        raise TerrainLoadError(f"{path}: the file holds an empty grid")
    if raw.shape[0] < 2 or raw.shape[1] < 2:
        raise TerrainLoadError(f"{path}: a terrain needs at least 2x2 samples, got {raw.shape[0]}x{raw.shape[1]}")
    if not (np.issubdtype(raw.dtype, np.integer) or np.issubdtype(raw.dtype, np.floating)) or raw.dtype == np.bool_:
        raise TerrainLoadError(f"{path}: heights must be integers or floats, got dtype {raw.dtype}")
    vals = raw.astype(np.float64)
    missing = ~np.isfinite(vals)
    if nodata is not None and np.isfinite(nodata):
        missing |= vals == float(nodata)
    n_missing = int(missing.sum())
    if n_missing == vals.size:
        raise TerrainLoadError(f"{path}: all {vals.size} samples are no-data")
    if n_missing:
        vals = fill_nodata(vals, missing)
        warnings.warn(f"{path}: {n_missing} no-data samples ({100 * n_missing / vals.size:.2f} %) filled by "
                      "neighbour averaging", NoDataWarning, stacklevel=3)
    heights = (vals * scale).astype(np.float32)
    if north_up:
        heights = heights[::-1]
        if texture is not None:
            texture = texture[::-1]
    try:
        hf = HeightField(np.ascontiguousarray(heights), spacing, origin, name or Path(path).stem,
                         None if texture is None else np.ascontiguousarray(texture), n_missing, str(path), list(notes))
    except TerrabenchError as exc:
        raise TerrainLoadError(f"{path}: {exc}") from None
    return hf


def _need(path, what, value):
    if value is None:
        raise TerrainLoadError(f"{path}: the file does not give the {what}; pass it (--{what.replace(' ', '-')})")
    return value


def load_png16(path, *, vertical_scale=None, spacing=None, texture_path=None, name=None) -> HeightField:
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
    return _finish(path, arr, scale=float(_need(path, "vertical scale", vertical_scale)),
                   spacing=float(_need(path, "spacing", spacing)), texture=tex, name=name)


def load_texture(path, cells_shape) -> np.ndarray:
    """Load an RGB texture (north-up, uint8) whose size must equal the height grid's cells (rows-1, cols-1)."""
    from PIL import Image, UnidentifiedImageError
    try:
        with Image.open(path) as im:
            tex = np.array(im.convert("RGB"))
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise TerrainLoadError(f"{path}: not a readable image ({exc})") from None
    if tex.shape[:2] != tuple(cells_shape):
        raise TerrainLoadError(f"{path}: texture is {tex.shape[1]}x{tex.shape[0]}, the height grid has "
                               f"{cells_shape[1]}x{cells_shape[0]} cells (texels are cell-centred)")
    return tex


def load_geotiff(path, *, vertical_scale=None, spacing=None, name=None) -> HeightField:
    """Load a single-band GeoTIFF via tifffile, using GDAL_NODATA and ModelPixelScale when present."""
    import tifffile
    try:
        with tifffile.TiffFile(path) as tif:
            page = tif.pages[0]
            arr = page.asarray()
            tags = {t.name: t.value for t in page.tags.values()}
    except Exception as exc:  # tifffile raises many types for corrupt files
        raise TerrainLoadError(f"{path}: not a readable TIFF ({type(exc).__name__}: {exc})") from None
    if arr.ndim == 3 and arr.shape[-1] == 1:
        arr = arr[..., 0]
    nodata = None
    if "GDAL_NODATA" in tags:
        try:
            nodata = float(str(tags["GDAL_NODATA"]).strip().strip("\x00"))
        except ValueError:
            raise TerrainLoadError(f"{path}: GDAL_NODATA tag {tags['GDAL_NODATA']!r} is not a number") from None
    notes = []
    if spacing is None and "ModelPixelScaleTag" in tags:
        sx, sy = float(tags["ModelPixelScaleTag"][0]), float(tags["ModelPixelScaleTag"][1])
        if sx <= 0 or abs(sx - sy) > 1e-9 * max(sx, sy):
            raise TerrainLoadError(f"{path}: pixel scale {sx} x {sy} is not square; pass --spacing")
        spacing = sx
        if sx < 0.01:
            notes.append(f"pixel scale {sx} looks like degrees; pass --spacing in metres to override")
    return _finish(path, arr, scale=1.0 if vertical_scale is None else float(vertical_scale),
                   spacing=float(_need(path, "spacing", spacing)), nodata=nodata, name=name, notes=notes)


def load_npy(path, *, vertical_scale=None, spacing=None, name=None) -> HeightField:
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
                    raise TerrainLoadError(f"{path}: 'spacing' must hold one number or (x, y) metres, "
                                           f"got shape {stored.shape}")
                spacing = float(stored.reshape(-1)[0]) if stored.size == 1 else tuple(float(v) for v in stored)
    else:
        arr = data
    return _finish(path, np.asarray(arr), scale=1.0 if vertical_scale is None else float(vertical_scale),
                   spacing=_need(path, "spacing", spacing), north_up=False, name=name)


def load_hgt(path, *, vertical_scale=None, spacing=None, name=None) -> HeightField:
    """Load an SRTM .hgt tile (1201² 3-arc-second or 3601² 1-arc-second big-endian int16, -32768 = no data)."""
    size = os.path.getsize(path)
    side = {1201 * 1201 * 2: 1201, 3601 * 3601 * 2: 3601}.get(size)
    if side is None:
        raise TerrainLoadError(f"{path}: {size} bytes is not an SRTM tile (1201² or 3601² int16 samples)")
    arr = np.fromfile(path, dtype=">i2").reshape(side, side)
    # one arc-second of latitude is about 30.87 m; longitude spacing shrinks with latitude (not corrected)
    default = 92.6 if side == 1201 else 30.87
    notes = [] if spacing is not None else [f"SRTM spacing taken as {default} m (arc-seconds at the equator)"]
    return _finish(path, arr, scale=1.0 if vertical_scale is None else float(vertical_scale),
                   spacing=float(spacing if spacing is not None else default), nodata=SRTM_NODATA, name=name,
                   notes=notes)


def load_raw(path, *, shape, dtype, vertical_scale=1.0, spacing=None, north_up=True, nodata=None,
             name=None) -> HeightField:
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
    arr = np.fromfile(path, dtype=dt).reshape(rows, cols)
    return _finish(path, arr, scale=float(vertical_scale), spacing=float(_need(path, "spacing", spacing)),
                   north_up=north_up, nodata=nodata, name=name)


def load_terrain(path, **options) -> HeightField:
    """Load any supported height-field file, choosing the reader by suffix; options go to that reader."""
    p = Path(path)
    if not p.exists():
        raise TerrainLoadError(f"{path}: no such file")
    if p.is_dir():
        raise TerrainLoadError(f"{path}: is a folder, not a height-field file")
    if p.stat().st_size == 0:
        raise TerrainLoadError(f"{path}: the file is empty")
    kind = SUFFIXES.get(p.suffix.lower())
    if kind is None:
        raise TerrainLoadError(f"{path}: unknown suffix {p.suffix!r}; supported: {', '.join(sorted(SUFFIXES))}")
    options = {k: v for k, v in options.items() if v is not None}
    reader = {"png": load_png16, "tiff": load_geotiff, "npy": load_npy, "npz": load_npy, "hgt": load_hgt,
              "raw": load_raw}[kind]
    if kind == "raw" and ("shape" not in options or "dtype" not in options):
        raise TerrainLoadError(f"{path}: a raw grid needs an explicit shape (--raw-shape ROWSxCOLS) and dtype (--raw-dtype)")
    try:
        return reader(str(p), **options)
    except TypeError as exc:
        raise TerrainLoadError(f"{path}: option not accepted by the {kind} reader ({exc})") from None


def save_npz(hf: HeightField, path) -> None:
    """Write heights (south-up, metres) and spacing (x, y metres) to an .npz that load_npy reads back."""
    np.savez(path, heights=hf.heights, spacing=np.array([hf.spacing_x, hf.spacing_y], dtype=np.float64))
