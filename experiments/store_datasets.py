"""Spec datasets served from a tile store's virtual periodic extension, named ``STORE@periodicSIZE``.

STORE is a tile store's folder (``terrabench prepare``) or a bundled dataset's name (``puget``). A bundled
dataset's store is prepared once, at the spec's tile size, into the cache folder (``TERRABENCH_CACHE``, else
``$XDG_CACHE_HOME/terrabench``, else ``~/.cache/terrabench``): written under a temporary name and renamed, so
that runs side by side and an interrupted preparation never leave a partial store under the final name. SIZE is
samples a side, k x the store's cells + 1 (``hybrid.tiles.periodic``): ``puget@periodic16385`` is the Puget
model repeated 16 x 16 times, 16385² samples (1 GiB of heights) that are never written anywhere.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

from hybrid.errors import TerrabenchError

PERIODIC = "@periodic"
BUNDLED_STORES = {"puget": 1024}  # bundled datasets a store can be made of: their cells a side (the period)
MAX_SIZE = (1 << 24) + 1  # the largest extension hybrid.tiles.periodic serves, samples a side


def split_periodic(text, what: str = "") -> tuple[str, int] | None:
    """(store, size in samples a side) of a 'STORE@periodicSIZE' dataset name; None for any other name (``what``
    prefixes the error)."""
    base, sep, rest = str(text).rpartition(PERIODIC)
    if not sep:
        return None
    if not base or not rest.isdigit():
        raise TerrabenchError(
            f"{what}dataset {text!r}: a periodic extension is written STORE@periodicSIZE, SIZE samples "
            "a side (e.g. puget@periodic16385)"
        )
    return base, int(rest)


def check_periodic(text: str, what: str) -> None:
    """Refuse by name a 'STORE@periodicSIZE' whose size cannot extend a bundled store (a store folder's size is
    checked when it is opened)."""
    periodic = split_periodic(text)
    assert periodic is not None  # called with 'STORE@periodicSIZE' names only
    base, size = periodic
    period = BUNDLED_STORES.get(base)
    if period is not None and not (period + 1 < size <= MAX_SIZE and (size - 1) % period == 0):
        raise TerrabenchError(
            f"{what}: {base}'s periodic extension must be k x {period} + 1 samples a side, k >= 2, "
            f"at most {MAX_SIZE}, got {size} (e.g. {base}{PERIODIC}{16 * period + 1})"
        )


def open_periodic_dataset(text: str, tile_size: int):
    """The StoredTerrain of 'STORE@periodicSIZE' (a bundled store prepared at tile_size cells when missing)."""
    from hybrid.tiles.periodic import open_periodic

    periodic = split_periodic(text)
    assert periodic is not None  # called with 'STORE@periodicSIZE' names only
    base, size = periodic
    return open_periodic(bundled_store(base, tile_size) if base in BUNDLED_STORES else base, size)


def cache_folder() -> Path:
    """The folder that keeps bundled datasets' tile stores (TERRABENCH_CACHE, else the user's cache), made."""
    env = os.environ.get("TERRABENCH_CACHE")
    folder = Path(env) if env else Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "terrabench"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TerrabenchError(
            f"cannot create the cache folder {folder} ({exc.strerror or exc}); set "
            "TERRABENCH_CACHE to a writable folder"
        ) from None
    return folder


def _complete(path: Path) -> bool:
    """Whether path holds a finished tile store with its node arrays (what prepare_store writes last)."""
    try:
        attrs = json.loads((path / "zarr.json").read_text()).get("attributes", {})
    except (OSError, ValueError):
        return False
    return bool(attrs.get("complete") and attrs.get("nodes") and attrs.get("node_blocks"))


def bundled_store(name: str, tile_size: int) -> Path:
    """The tile store of a bundled dataset at tile_size cells a tile, prepared into the cache folder if missing."""
    from hybrid.terrain.datasets import get_dataset
    from hybrid.terrain.grid_sources import HeightFieldSource
    from hybrid.terrain.stored import STORE_VERSION
    from hybrid.tiles.store import prepare_store

    folder = cache_folder()
    final = folder / f"{name}-t{int(tile_size)}-v{STORE_VERSION}.store"
    if _complete(final):
        return final
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", dir=folder))
    except OSError as exc:
        raise TerrabenchError(
            f"cannot write in the cache folder {folder} ({exc.strerror or exc}); set "
            "TERRABENCH_CACHE to a writable folder"
        ) from None
    try:
        prepare_store(HeightFieldSource(get_dataset(name)), tmp, tile_size)
        try:
            tmp.rename(final)
        except OSError:  # another process renamed its copy first: keep that one
            if not _complete(final):
                raise TerrabenchError(f"{final} exists and is not a finished tile store; remove it") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return final
