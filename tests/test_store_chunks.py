"""Whole-chunk reads of a tile store (hybrid.terrain.store_chunks): the same samples as Zarr's own read, for every
tile of a store and of its periodic extension, read without Zarr's per-call path, and a damaged chunk refused by
name, never decoded into wrong samples."""

import shutil

import numpy as np
import pytest
import zarr

from hybrid.errors import StoreDamagedError
from hybrid.terrain import store_manifest
from hybrid.terrain.grid_sources import FractalSource
from hybrid.terrain.store_chunks import chunk_reader, sliced_reader
from hybrid.terrain.store_manifest import checked_store
from hybrid.terrain.stored import open_store
from hybrid.tiles.periodic import open_periodic
from hybrid.tiles.store import StorePyramid, prepare_store


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A 257² fractal store of tiles of 32 (levels 0..3), square with a period of 256 cells."""
    return prepare_store(FractalSource(257, seed=5), tmp_path_factory.mktemp("chunks") / "s", 32)


def _through_zarr(p: StorePyramid) -> StorePyramid:
    """The same pyramid reading its chunks through Zarr's slicing (the general path)."""
    p._readers = {level: sliced_reader(a, (p.n, p.n)) for level, a in p._levels.items()}
    return p


def _all_tiles_equal(terrain) -> int:
    direct, general = StorePyramid(terrain), _through_zarr(StorePyramid(terrain))
    count = 0
    for level in range(direct.max_level + 1):
        for key in direct.keys(level):
            a, b = direct.samples(key), general.samples(key)
            assert a.dtype == b.dtype == np.float32 and a.shape == b.shape == (33, 33), key
            assert a.tobytes() == b.tobytes(), key  # bit for bit, NaN payloads included
            count += 1
    return count


def test_every_tile_read_directly_equals_zarrs_read(store):
    assert _all_tiles_equal(open_store(store)) == 64 + 16 + 4 + 1


def test_every_tile_of_a_periodic_extension_equals_zarrs_read(store):
    # 1025² over a period of 256: seam tiles, wrapped chunks and the strided levels above the source's
    assert _all_tiles_equal(open_periodic(store, 1025)) == 1024 + 256 + 64 + 16 + 4 + 1


def test_each_chunk_equals_zarrs_slice_including_the_clipped_last_ones(store):
    t = open_store(store)
    for level in range(4):
        a = t.store[f"levels/{level}"]
        read = chunk_reader(a, (32, 32))
        rows, cols = a.shape
        for cy in range(-(-rows // 32)):
            for cx in range(-(-cols // 32)):
                got, want = read(cy, cx), a[cy * 32 : (cy + 1) * 32, cx * 32 : (cx + 1) * 32]
                assert got.shape == want.shape and got.dtype == want.dtype and np.array_equal(got, want)
        with pytest.raises(IndexError):
            read(-(-rows // 32), 0)


def test_tile_reads_go_to_the_chunk_files_not_through_zarr(store, monkeypatch):
    cls, files, gets = store_manifest._checked_class(), [], []
    original_get, original_file = cls.get, cls.read_file

    async def get(self, key, prototype=None, byte_range=None):
        gets.append(key)
        return await original_get(self, key, prototype, byte_range)

    def read_file(self, key):
        files.append(key)
        return original_file(self, key)

    monkeypatch.setattr(cls, "get", get)
    monkeypatch.setattr(cls, "read_file", read_file)
    p = StorePyramid(store)
    gets.clear()
    p.samples(p.keys(0)[9])  # tile (1, 1) of 8 x 8: its chunk and three neighbours'
    assert sorted(files) == [f"levels/0/c/{y}/{x}" for y in (1, 2) for x in (1, 2)]
    assert not [k for k in gets if k.startswith("levels/")]


@pytest.mark.parametrize("how", ["garble", "truncate", "delete"])
def test_a_damaged_chunk_is_refused_by_name(store, tmp_path, how):
    copy = tmp_path / "s"
    shutil.copytree(store, copy)
    path = copy / "levels/1/c/2/3"
    raw = bytearray(path.read_bytes())
    if how == "garble":
        raw[len(raw) // 2] ^= 0x5A
        path.write_bytes(bytes(raw))
    elif how == "truncate":
        path.write_bytes(bytes(raw[:-7]))
    else:
        path.unlink()
    p = StorePyramid(copy)
    key = next(k for k in p.keys(1) if (k.ty, k.tx) == (2, 3))
    reason = {"garble": "fails its checksum", "truncate": "is short", "delete": "is missing"}[how]
    with pytest.raises(StoreDamagedError, match=rf"array levels/1, chunk \(2, 3\).*{reason}"):
        p.samples(key)


def test_a_garbled_chunk_of_a_store_without_manifest_is_refused_by_name(store, tmp_path):
    copy = tmp_path / "old"
    shutil.copytree(store, copy)
    del zarr.open_group(str(copy), mode="r+").attrs["manifest"]
    (copy / store_manifest.MANIFEST).unlink()
    (copy / "levels/0/c/0/0").write_bytes(b"not a zstd frame" * 8)
    p = StorePyramid(copy)
    with pytest.raises(StoreDamagedError, match=r"array levels/0, chunk \(0, 0\).*cannot be decoded"):
        p.samples(p.keys(0)[0])


@pytest.mark.parametrize("codecs", ["bytes", "gzip", "blosc", "other chunks"])
def test_other_layouts_read_as_zarr_reads_them(tmp_path, codecs):
    from zarr.codecs import BloscCodec, BytesCodec, GzipCodec

    compressors = {"bytes": None, "gzip": GzipCodec(level=3), "blosc": BloscCodec(), "other chunks": None}[codecs]
    g = zarr.open_group(str(tmp_path / "g"), mode="w")
    chunks = (16, 32) if codecs == "other chunks" else (32, 32)
    a = g.create_array("a", shape=(70, 45), chunks=chunks, dtype="f4", fill_value=np.nan, compressors=compressors)
    assert isinstance(a.metadata.codecs[0], BytesCodec)
    values = np.random.default_rng(2).normal(size=(70, 45)).astype(np.float32)
    a[:64] = values[:64]  # the last rows' chunks stay unwritten: the fill value
    opened = zarr.open_group(store=checked_store(tmp_path / "g", None), mode="r")["a"]
    read = chunk_reader(opened, (32, 32))
    assert (read.__name__ == "read") == (codecs in ("bytes", "gzip"))  # decoded here, else through Zarr
    for cy in range(3):
        for cx in range(2):
            want = opened[cy * 32 : (cy + 1) * 32, cx * 32 : (cx + 1) * 32]
            assert np.array_equal(read(cy, cx), want, equal_nan=True), (cy, cx)
    assert np.isnan(read(2, 1)).all() and read(2, 1).shape == (6, 13)
