"""A tile store's manifest: every file's size and CRC-32, written by prepare and checked on every read.

``prepare`` ends by listing every file of the store but two (the group's own ``zarr.json``, whose attributes are
the header and are checked by content when the store is opened, and the manifest itself) with its byte size and
zlib CRC-32 in ``manifest.json``, then records the manifest's own size and CRC-32 in the header (attribute
``manifest``) and marks the store complete. A store opened by ``open_store`` reads through ``CheckedStore``: each
listed file (an array's ``zarr.json`` or a chunk) must be present with its recorded size and checksum when Zarr
reads it, else one TerrabenchError names the store, the array, the chunk and the fix; a chunk is never filled
in. Opening also checks every listed ``zarr.json``, so a removed array or folder is named before any frame.

A store prepared before manifests has no ``manifest`` attribute: it reads as before, unchecked, and
``terrabench info STORE --verify`` says it cannot be verified; running the same prepare command on it records one
(trusting what is on disk then).
"""

from __future__ import annotations

import functools
import json
import os
import zlib
from pathlib import Path

from hybrid.errors import StoreDamagedError, TerrabenchError

MANIFEST = "manifest.json"
MANIFEST_FORMAT = "terrabench-store-manifest"
HEADER = "zarr.json"  # the group's metadata: its attributes are the store's header


def crc32(data) -> int:
    """CRC-32 (zlib) of a bytes-like object, as an unsigned int."""
    return zlib.crc32(data) & 0xFFFFFFFF


def describe(key: str) -> str:
    """A store file's key as words: the array and the chunk index, or the array's or group's metadata."""
    if "/c/" in key:
        array, chunk = key.split("/c/", 1)
        return f"array {array}, chunk ({', '.join(chunk.split('/'))}) (file {key})"
    if key.endswith(HEADER):
        parent = key[: -len(HEADER)].rstrip("/")
        return f"the metadata of {parent or 'the group'} (file {key})"
    return f"file {key}"


def damaged(store, key: str, reason: str) -> StoreDamagedError:
    """The one error for a damaged file of a store: names the store, the array and chunk, and the fix."""
    return StoreDamagedError(
        f"{store}: tile store is damaged: {describe(key)} {reason}; run terrabench prepare again "
        f"on its input into a new folder (or remove {store} first)"
    )


def fault(data, entry) -> str | None:
    """Why file bytes (None: missing) do not match a manifest entry [bytes, crc32], or None when they do."""
    if data is None:
        return "is missing"
    size = len(data)
    if size != entry[0]:
        return f"is {'short' if size < entry[0] else 'long'} ({size} bytes, {entry[0]} recorded)"
    if crc32(data) != entry[1]:
        return "fails its checksum"
    return None


def _listed(root: Path) -> list[str]:
    """Keys (POSIX paths relative to root) of every file the manifest covers, sorted."""
    keys = []
    for folder, _dirs, files in os.walk(root):
        for f in files:
            key = (Path(folder) / f).relative_to(root).as_posix()
            if key not in (HEADER, MANIFEST) and not key.startswith(".") and not f.endswith(".tmp"):
                keys.append(key)
    return sorted(keys)


def record_manifest(root) -> dict:
    """Write root/manifest.json listing every file's [bytes, crc32]; returns the header's ``manifest`` attribute
    (the manifest's own size and CRC-32, and the count of files)."""
    root = Path(root)
    files = {}
    for key in _listed(root):
        data = (root / key).read_bytes()
        files[key] = [len(data), crc32(data)]
    text = manifest_bytes(files)
    tmp = root / (MANIFEST + ".tmp")
    tmp.write_bytes(text)
    os.replace(tmp, root / MANIFEST)
    return manifest_attribute(text, files)


def manifest_bytes(files: dict) -> bytes:
    """The manifest file's bytes listing ``files`` (key -> [bytes, crc32])."""
    return json.dumps(
        {"format": MANIFEST_FORMAT, "version": 1, "checksum": "crc32", "files": files}, separators=(",", ":")
    ).encode()


def manifest_attribute(text: bytes, files: dict) -> dict:
    """The header's ``manifest`` attribute of a manifest file's bytes: its size and CRC-32, and the count of files."""
    return {"file": MANIFEST, "bytes": len(text), "crc32": crc32(text), "files": len(files)}


def load_manifest(root, attrs: dict) -> dict | None:
    """The manifest's files (key -> [bytes, crc32]) of a store whose header is ``attrs``; None for a store
    prepared before manifests; refused by name when the manifest is missing or damaged."""
    info = attrs.get("manifest")
    if not info:
        return None
    path = Path(root) / MANIFEST
    try:
        data = path.read_bytes()
    except OSError:
        data = None
    reason = fault(data, [int(info["bytes"]), int(info["crc32"])])
    if reason is None:
        assert data is not None  # fault calls a missing file a fault
        try:
            body = json.loads(data)
            if body.get("format") == MANIFEST_FORMAT:
                return {k: list(v) for k, v in body["files"].items()}
        except (ValueError, AttributeError, KeyError, TypeError):
            pass
        reason = "is not a manifest"
    raise damaged(root, MANIFEST, reason)


def bad_files(root, files: dict, only_metadata: bool = False) -> list[tuple[str, str]]:
    """(key, reason) of every manifest file (only the ``zarr.json`` ones with only_metadata) that is missing,
    of another size or fails its checksum; reads each file once."""
    root = Path(root)
    bad = []
    for key, entry in files.items():
        if only_metadata and not key.endswith(HEADER):
            continue
        try:
            data = (root / key).read_bytes()
        except OSError:
            data = None
        reason = fault(data, entry)
        if reason:
            bad.append((key, reason))
    return bad


def checked_store(root, files: dict | None):
    """A read-only Zarr store over root whose reads of manifest files are checked (files None: unchecked)."""
    return _checked_class()(root, files)


@functools.cache
def _checked_class():
    """The CheckedStore class (made on first use, so that importing this module does not import Zarr)."""
    from zarr.storage import LocalStore

    class CheckedStore(LocalStore):
        """A read-only LocalStore that checks each manifest file it reads (size, CRC-32), raising ``damaged``."""

        def __init__(self, root, files: dict | None):
            super().__init__(str(root), read_only=True)
            self.store_path, self.files = str(root), files or {}

        async def get(self, key, prototype=None, byte_range=None):
            data = await super().get(key, prototype, byte_range)
            entry = self.files.get(key)
            if entry is None or byte_range is not None:
                return data
            reason = fault(None if data is None else data.as_numpy_array(), entry)
            if reason:
                raise damaged(self.store_path, key, reason)
            return data

        def read_file(self, key: str) -> bytes | None:
            """A file's bytes read in the caller's thread (None: absent and not listed), checked as ``get`` does."""
            try:
                data = (Path(self.store_path) / key).read_bytes()
            except (FileNotFoundError, NotADirectoryError):
                data = None
            entry = self.files.get(key)
            reason = None if entry is None else fault(data, entry)
            if reason:
                raise damaged(self.store_path, key, reason)
            return data

        def with_read_only(self, read_only: bool = False):
            if not read_only:
                raise TerrabenchError(f"{self.store_path}: an opened tile store is read-only")
            return self

    return CheckedStore
