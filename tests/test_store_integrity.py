"""A tile store's manifest: a deleted, truncated or garbled file of any kind makes `render` (each method that reads
it) and `info --verify` exit 2 with one message naming the file, and write no image; a clean store renders and
verifies; a store prepared before manifests reads as before, cannot be verified, and gets one when prepared again."""

import shutil

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from experiments.cli import main
from hybrid.errors import TerrabenchError
from hybrid.terrain import store_manifest
from hybrid.terrain.grid_sources import FractalSource
from hybrid.terrain.store_manifest import MANIFEST, bad_files, load_manifest
from hybrid.terrain.stored import _header, open_store
from hybrid.tiles.store import prepare_store

METHODS = ("raycast", "raster", "hybrid")
VIEW = ["--size", "96x54", "--tile-size", "32", "--flight", "flyover", "--frame", "1"]


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """A small complete store (129² fractal, tiles of 32: levels 0..2)."""
    return prepare_store(FractalSource(129, seed=3), tmp_path_factory.mktemp("integrity") / "s", 32)


def _render(store, method, out):
    return main(["render", "--dataset", str(store), "--method", method, "--out", str(out)] + VIEW)


@pytest.fixture(scope="module")
def reads(clean, ctx, tmp_path_factory):
    """Per method, the chunk keys its render reads beyond those read to place the camera (the frame's own)."""
    from experiments.cli.options import TerrainOptions, ViewOptions

    cls, seen = store_manifest._checked_class(), []
    original, original_file = cls.get, cls.read_file

    async def recording(self, key, prototype=None, byte_range=None):
        seen.append(key)
        return await original(self, key, prototype, byte_range)

    def recording_file(self, key):  # chunks read directly (hybrid.terrain.store_chunks)
        seen.append(key)
        return original_file(self, key)

    out = {}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cls, "get", recording)
        mp.setattr(cls, "read_file", recording_file)
        ViewOptions(size=(96, 54), flight="flyover", frame=1).view(TerrainOptions(str(clean)).load())
        camera = set(seen)
        for method in METHODS:
            seen.clear()
            assert _render(clean, method, tmp_path_factory.mktemp("r") / "a.png") == 0
            out[method] = sorted(k for k in set(seen) - camera if "/c/" in k)
    return out


def _damage(path, how):
    """Delete, truncate to half, or overwrite 4 bytes in the middle (same size) of a file."""
    if how == "delete":
        path.unlink()
    elif how == "truncate":
        path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    else:
        b = bytearray(path.read_bytes())
        mid = len(b) // 2
        b[mid : mid + 4] = bytes(x ^ 0xA5 for x in b[mid : mid + 4])
        path.write_bytes(bytes(b))


def _key(kind, method, reads):
    """The file of this kind to damage: for chunks, one the method's frame reads."""
    prefix = {"level chunk": "levels/", "node block chunk": "nodes/blocks/"}.get(kind)
    if prefix:
        return next(k for k in reads[method] if k.startswith(prefix))
    return {
        "zmin chunk": "zmin/0/c/0/0",
        "zmax chunk": "zmax/1/c/0/0",
        "error chunk": "error/2/c/0/0",
        "node array chunk": "nodes/effective/0/c/1/2",
        "array zarr.json": "levels/1/zarr.json",
        "group zarr.json": "zarr.json",
        "subgroup zarr.json": "nodes/zarr.json",
        "manifest": MANIFEST,
    }[kind]


KINDS = (
    "level chunk",
    "zmin chunk",
    "zmax chunk",
    "error chunk",
    "node block chunk",
    "array zarr.json",
    "group zarr.json",
    "subgroup zarr.json",
    "manifest",
)
# who reads what: the raster strategies read a tile's node block, never the node arrays a store with blocks holds
READERS = {"node block chunk": ("raster", "hybrid"), "node array chunk": ()}


@pytest.mark.parametrize("how", ["delete", "truncate", "garble"])
@pytest.mark.parametrize("kind", KINDS + ("node array chunk",))
def test_a_damaged_file_is_refused_by_name_by_every_reader(clean, reads, tmp_path, capsys, kind, how):
    methods = READERS.get(kind, METHODS)
    for method in methods + ("verify",):
        store = tmp_path / f"s-{method}"
        shutil.copytree(clean, store)
        key = _key(kind, "raster" if method == "verify" else method, reads)
        _damage(store / key, how)
        out = tmp_path / f"out-{method}" / "a.png"
        out.parent.mkdir()
        capsys.readouterr()
        rc = _render(store, method, out) if method != "verify" else main(["info", str(store), "--no-gl", "--verify"])
        err = capsys.readouterr().err
        assert rc == 2, (method, key, err)
        assert err.startswith("terrabench: error: ") and "Traceback" not in err, err
        assert key in err and str(store) in err and "prepare" in err, (method, key, err)
        assert not any(out.parent.iterdir()), method  # no image, no depth


def test_a_clean_store_renders_and_verifies(clean, reads, tmp_path, capsys):
    assert main(["info", str(clean), "--no-gl", "--verify"]) == 0
    text = capsys.readouterr().out
    n = len(load_manifest(clean, _header(clean, clean)))
    assert f"verified:    {n} files match" in text and "tiles:       32 cells, levels 0..2, 21 tiles" in text
    assert "node arrays: 7 levels" in text and f"manifest:    {n} files" in text and "bytes:" in text
    for method in METHODS:  # every method's frame reads level chunks
        assert any(k.startswith("levels/") for k in reads[method]), method
    assert any(k.startswith("nodes/blocks/") for k in reads["raster"])
    assert not any(k.startswith("nodes/blocks/") for k in reads["raycast"])


def test_info_verify_lists_every_damaged_file(clean, tmp_path, capsys):
    store = tmp_path / "s"
    shutil.copytree(clean, store)
    keys = ["levels/0/c/1/1", "nodes/blocks/0/c/2/3/0/0", "zmin/2/c/0/0"]
    for key, how in zip(keys, ("delete", "truncate", "garble")):
        _damage(store / key, how)
    assert main(["info", str(store), "--no-gl", "--verify"]) == 2
    err = capsys.readouterr().err
    assert "3 of" in err and "is missing" in err and "is short" in err and "fails its checksum" in err
    assert all(k in err for k in keys) and "array levels/0, chunk (1, 1)" in err
    assert main(["info", "--dataset", "fbm", "--no-gl", "--verify"]) == 2
    assert "--verify applies to a tile store" in capsys.readouterr().err


def test_a_store_from_before_manifests_reads_and_gets_one_when_prepared_again(clean, tmp_path, capsys):
    import zarr

    store = tmp_path / "old"
    shutil.copytree(clean, store)
    g = zarr.open_group(str(store), mode="r+")
    del g.attrs["manifest"]
    (store / MANIFEST).unlink()
    t = open_store(store)
    assert t.heights[5, 7] == open_store(clean).heights[5, 7]
    assert main(["info", str(store), "--no-gl"]) == 0
    assert "manifest:    none (prepared before manifests" in capsys.readouterr().out
    assert main(["info", str(store), "--no-gl", "--verify"]) == 2
    assert "has no manifest" in capsys.readouterr().err
    prepare_store(FractalSource(129, seed=3), store, 32)  # the same prepare records one
    assert main(["info", str(store), "--no-gl", "--verify"]) == 0
    (store / "levels/0/c/0/0").unlink()
    with pytest.raises(TerrabenchError, match=r"levels/0, chunk \(0, 0\).*is missing"):
        open_store(store).heights[0, 0]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_truncation_or_changed_byte_of_any_file_is_found(clean, data):
    files = load_manifest(clean, _header(clean, clean))
    key = data.draw(st.sampled_from(sorted(files)), label="file")
    original = (clean / key).read_bytes()
    raw = bytearray(original)
    if data.draw(st.booleans(), label="truncate"):
        raw = raw[: data.draw(st.integers(0, len(raw) - 1), label="keep")]
    else:
        at = data.draw(st.integers(0, len(raw) - 1), label="at")
        raw[at] ^= data.draw(st.integers(1, 255), label="xor")
    (clean / key).write_bytes(bytes(raw))
    try:  # damaged in place, restored before the next example
        assert [k for k, _ in bad_files(clean, files)] == [key]
    finally:
        (clean / key).write_bytes(original)
    assert bad_files(clean, files) == []


def _spec(tmp_path, store, name="s"):
    path = tmp_path / f"{name}.toml"
    path.write_text(
        f'name = "{name}"\ndatasets = ["{store}"]\nflights = ["flyover"]\nframes = 2\n'
        'policies = ["raster", "raycast", "hybrid"]\ntaus = [0.6667]\nsizes = ["64x36"]\n'
        "repeats = 3\ntile_size = 32\naccuracy = false\n"
    )
    return path


def test_run_and_scale_take_a_store_and_refuse_a_damaged_one_by_name(clean, ctx, tmp_path, capsys):
    import pandas as pd

    runs = tmp_path / "runs"
    assert main(["run", str(_spec(tmp_path, clean)), "--runs", str(runs), "--quiet"]) == 0
    f = pd.read_parquet(runs / "s" / "frames.parquet")
    assert sorted(set(f["policy"])) == ["hybrid", "raster", "raycast"] and len(f) == 6
    assert set(f["dataset"]) == {str(clean)} and (f["tiles"] > 0).all() and (f["wall_ms"] > 0).all()
    assert (
        main(
            [
                "scale",
                str(clean),
                "--frames",
                "2",
                "--size",
                "64x36",
                "--methods",
                "raycast,raster",
                "--out",
                str(tmp_path / "scale"),
            ]
        )
        == 0
    )
    text = (tmp_path / "scale" / "scaling.md").read_text()
    assert "| 129 | fractal-129-s3 | raycast | 2 |" in text and "| 129 | fractal-129-s3 | raster | 2 |" in text
    bad = tmp_path / "bad"
    shutil.copytree(clean, bad)
    _damage(bad / "levels/2/c/0/0", "garble")  # the root tile's chunk: every method reads it
    capsys.readouterr()
    assert (
        main(
            [
                "scale",
                str(bad),
                "--frames",
                "2",
                "--size",
                "64x36",
                "--methods",
                "raster",
                "--out",
                str(tmp_path / "scale-bad"),
            ]
        )
        == 2
    )
    assert "levels/2, chunk (0, 0)" in capsys.readouterr().err and not (tmp_path / "scale-bad").exists()
    for chunk in (bad / "levels/1/c").rglob("*"):  # a flight of few pixels draws coarse tiles
        if chunk.is_file():
            _damage(chunk, "garble")
    assert main(["run", str(_spec(tmp_path, bad, "b")), "--runs", str(runs), "--quiet"]) == 1
    err = capsys.readouterr().err  # each configuration failed, by name
    assert err.count("fails its checksum") == 3 and err.count(f"{bad}: tile store is damaged: array levels/") == 3
    assert not (runs / "b" / "frames.parquet").exists() or pd.read_parquet(runs / "b" / "frames.parquet").empty
