"""`terrabench info STORE [--verify]`: what a tile store holds, and every file checked against its manifest."""

from __future__ import annotations

import os
from pathlib import Path

from hybrid.errors import TerrabenchError


def _bytes_by_part(root: Path, files: dict | None) -> dict:
    """Bytes on disk per top-level part of the store (levels, zmin, nodes, ...), from the manifest or the disk."""
    sizes = (
        {k: v[0] for k, v in files.items()}
        if files
        else {
            (Path(d) / f).relative_to(root).as_posix(): (Path(d) / f).stat().st_size
            for d, _, fs in os.walk(root)
            for f in fs
        }
    )
    out: dict = {}
    for key, size in sizes.items():
        part = key.split("/")[0] if "/" in key else "(header)"
        out[part] = out.get(part, 0) + size
    return out


def _mib(n: int) -> str:
    return f"{n / 2**20:.2f} MiB" if n >= 2**20 else f"{n / 2**10:.1f} KiB"


def verify_store(path) -> int:
    """Check every file of a store against its manifest; prints the count checked; raises TerrabenchError listing
    each bad file (or saying the store has no manifest). Returns the number of files checked."""
    from hybrid.terrain.store_manifest import bad_files, describe, load_manifest
    from hybrid.terrain.stored import _header

    p = Path(path)
    files = load_manifest(p, _header(p, path))
    if files is None:
        raise TerrabenchError(
            f"{path}: tile store has no manifest (prepared before manifests), so it cannot be "
            "verified; run the same terrabench prepare command on it to record one"
        )
    bad = bad_files(p, files)
    if bad:
        lines = "\n".join(f"  {describe(k)} {why}" for k, why in bad)
        raise TerrabenchError(
            f"{path}: tile store is damaged: {len(bad)} of {len(files)} files do not match its "
            f"manifest:\n{lines}\nrun terrabench prepare again on its input into a new folder "
            f"(or remove {path} first)"
        )
    print(f"verified:    {len(files)} files match the manifest (sizes and CRC-32)")
    return len(files)


def describe_store(path, verify: bool = False) -> None:
    """Print a tile store's summary: samples, tiles, levels, node arrays, bytes by part and its manifest; with
    verify, check every file first (``verify_store``)."""
    from hybrid.terrain.store_manifest import load_manifest
    from hybrid.terrain.stored import open_store
    from hybrid.tiles.store import StorePyramid

    if verify:
        verify_store(path)
    t = open_store(path)
    print(t.summary())
    a = dict(t.store.attrs)
    pyr = StorePyramid(t)
    tiles = [len(pyr.keys(lev)) for lev in range(pyr.max_level + 1)]
    print(
        f"tiles:       {pyr.n} cells, levels 0..{pyr.max_level}, {sum(tiles)} tiles "
        f"({', '.join(f'{k}' for k in tiles)} by level)"
    )
    for lev in range(pyr.max_level + 1):
        arr = t.store[f"levels/{lev}"]
        print(f"level {lev}:     {arr.shape[1]} x {arr.shape[0]} samples, {arr.nchunks} chunks of {arr.chunks[0]}²")
    nodes = a.get("nodes")
    if nodes:
        print(
            f"node arrays: {nodes['levels']} levels over a square of {nodes['square']} cells, beta {nodes['beta']:g}, "
            f"form {nodes.get('form', 'combined')}; per-tile blocks: {'yes' if a.get('node_blocks') else 'no'}"
        )
    else:
        print("node arrays: none (the raster strategies refuse it until prepared again)")
    files = load_manifest(path, a)
    parts = _bytes_by_part(Path(path), files)
    print(f"bytes:       {_mib(sum(parts.values()))} ({', '.join(f'{k} {_mib(v)}' for k, v in sorted(parts.items()))})")
    if files is None:
        print(
            "manifest:    none (prepared before manifests: reads are not checked; the same prepare command records one)"
        )
    else:
        print(f"manifest:    {len(files)} files with sizes and CRC-32, checked on every read")
