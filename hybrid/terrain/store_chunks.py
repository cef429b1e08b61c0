"""Whole-chunk reads of a tile store's arrays: one file read, its manifest check, and the codecs called directly.

Zarr's own read of a chunk (``array[window]``) hands the selection to its event-loop thread and back and parses
it on the way; for a 256² float32 chunk that per-call overhead is most of its time (about 1.9 ms against 0.55 ms
for the file read, CRC-32 and zstd decode). ``chunk_reader`` reads a chunk's file in the caller's thread (a tile
store's loader thread), checks it against the manifest as ``CheckedStore.get`` does, and decodes it with numcodecs:
the same bytes through the same codecs, hence the same samples as Zarr's read, a chunk absent from disk and from
the manifest reading as the fill value as in Zarr. Arrays whose layout it does not decode itself (another chunk
shape than asked, sharding, array-to-array codecs, a codec other than zstd or gzip, a store without
``read_file``) are read through Zarr.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from hybrid.terrain.store_manifest import damaged

ChunkRead = Callable[[int, int], np.ndarray]


def sliced_reader(array, shape: tuple[int, int]) -> ChunkRead:
    """Chunk (cy, cx) of shape ``shape`` of any 2-D array-like, clipped to its grid, read by slicing it."""
    a, b = shape
    return lambda cy, cx: np.asarray(array[cy * a : (cy + 1) * a, cx * b : (cx + 1) * b])


def chunk_reader(array, shape: tuple[int, int]) -> ChunkRead:
    """Chunk (cy, cx) of a 2-D Zarr array, clipped to its grid (the array's dtype): its file decoded directly when
    the array is chunked by ``shape`` in a layout read here, else through Zarr."""
    decoders = _decoders(array, shape)
    if decoders is None:
        return sliced_reader(array, shape)
    meta, store = array.metadata, array.store
    order = meta.codecs[0].endian  # None for one-byte types
    endian = ">" if order is not None and order.value == "big" else "<"
    stored = meta.data_type.to_native_dtype().newbyteorder(endian)
    dtype, fill = stored.newbyteorder("="), meta.fill_value
    rows, cols = (int(s) for s in array.shape)
    size = int(np.prod(shape)) * stored.itemsize
    prefix = f"{array.path}/" if array.path else ""

    def read(cy: int, cx: int) -> np.ndarray:
        key = prefix + meta.encode_chunk_key((cy, cx))
        r, c = min(shape[0], rows - cy * shape[0]), min(shape[1], cols - cx * shape[1])
        if r <= 0 or c <= 0 or cy < 0 or cx < 0:
            raise IndexError(f"chunk ({cy}, {cx}) lies outside {array.path} of {rows}x{cols}")
        data = store.read_file(key)
        if data is None:  # never written (Zarr leaves out chunks of only the fill value)
            return np.full((r, c), fill, dtype)
        try:
            for codec in decoders:
                data = codec.decode(data)
        except Exception as exc:  # a codec's own error: the file is not what the store wrote
            raise damaged(store.store_path, key, f"cannot be decoded ({exc})") from None
        got = memoryview(data).nbytes
        if got != size:
            raise damaged(store.store_path, key, f"decodes to {got} bytes, {size} expected")
        full = np.frombuffer(data, stored).reshape(shape)
        out = full if (r, c) == shape else full[:r, :c]
        return np.ascontiguousarray(out, dtype=dtype)

    return read


def _decoders(array, shape: tuple[int, int]) -> list | None:
    """The numcodecs decoders, last applied first, of a Zarr v3 array chunked by ``shape`` whose codecs are bytes
    and then zstd or gzip, in a store with ``read_file``; None for any other array."""
    meta: Any = getattr(array, "metadata", None)
    if getattr(meta, "zarr_format", None) != 3 or not hasattr(getattr(array, "store", None), "read_file"):
        return None
    grid = getattr(meta.chunk_grid, "chunk_shape", None)
    if grid is None or tuple(int(s) for s in grid) != tuple(shape) or len(shape) != 2:
        return None
    from numcodecs import GZip, Zstd
    from zarr.codecs import BytesCodec, GzipCodec, ZstdCodec

    codecs = list(meta.codecs)
    if not codecs or type(codecs[0]) is not BytesCodec:
        return None
    out = []
    for codec in codecs[1:]:
        if type(codec) is ZstdCodec:
            out.append(Zstd(level=codec.level, checksum=codec.checksum))
        elif type(codec) is GzipCodec:
            out.append(GZip(level=codec.level))
        else:
            return None
    return out[::-1]
