"""Atomic changes to a tile store: new files staged inside it, one commit marker, and recovery when it is opened.

An edit written through to a stored terrain replaces some of the store's files (chunks of its arrays, the
manifest, the header ``zarr.json``). A ``Transaction`` stages each new file in ``.edit/<id>/`` in the store (the
manifest skips names that start with a dot), flushed to disk. Then it writes the commit marker
``.edit/commit.json`` (the stage, each key and its staged file, the header last) with one atomic rename: that is
the commit point.
Then each staged file is renamed over its key, and the marker and the stage are removed.

``recover`` runs before every read of a store's header (``hybrid.terrain.stored``). A committed transaction is
finished: a rename is atomic, so whatever is still staged is renamed. An uncommitted one is removed. A crash at any
point therefore leaves the store wholly before or wholly after the change. One writer at a time: two processes
must not change a store at once.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
from pathlib import Path

from hybrid.errors import TerrabenchError

EDIT_DIR = ".edit"
COMMIT = "commit.json"


def _write(path: Path, data: bytes) -> None:
    """Write bytes to a file and flush them to disk."""
    with open(path, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def _move(src: Path, dst: Path) -> None:
    """Rename src over dst (atomic on one file system)."""
    os.replace(src, dst)


def _sync_dir(path: Path) -> None:
    """Flush a directory's entries to disk (where the platform allows)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


class Transaction:
    """New files for a store, staged under ``.edit/<id>`` (one flat folder), committed at once by ``commit``."""

    def __init__(self, root):
        self.root = Path(root)
        recover(self.root)
        self.stage = self.root / EDIT_DIR / uuid.uuid4().hex
        self.stage.mkdir(parents=True)
        self.files: list[tuple[str, str]] = []  # (key: a POSIX path in the store, staged file name)
        self.committed = False

    def add(self, key: str, data: bytes) -> None:
        """Stage a key's new bytes."""
        name = str(len(self.files))
        _write(self.stage / name, data)
        self.files.append((key, name))

    def commit(self) -> None:
        """Make the staged files the store's: the commit marker (the commit point), then the renames, the header
        last."""
        _sync_dir(self.stage)
        order = sorted(self.files, key=lambda f: (f[0] == "zarr.json", f[0] == "manifest.json", f[0]))
        marker = self.root / EDIT_DIR / COMMIT
        _write(marker.with_suffix(".tmp"), json.dumps({"stage": self.stage.name, "files": order}).encode())
        _move(marker.with_suffix(".tmp"), marker)
        _sync_dir(marker.parent)
        self.committed = True
        _finish(self.root, self.stage, order)

    def abort(self) -> None:
        """Drop the staged files, unless committed (then recovery finishes the change)."""
        if not self.committed:
            shutil.rmtree(self.stage, ignore_errors=True)


def _finish(root: Path, stage: Path, files: list) -> None:
    """Rename every still-staged file over its key, in order, then remove the marker and the stage."""
    for key, name in files:
        src = stage / name
        if src.exists():
            (root / key).parent.mkdir(parents=True, exist_ok=True)
            _move(src, root / key)
    _sync_dir(root)
    (root / EDIT_DIR / COMMIT).unlink(missing_ok=True)
    shutil.rmtree(root / EDIT_DIR, ignore_errors=True)


def recover(root) -> str | None:
    """Finish a store's committed change or drop an uncommitted one; returns "finished", "dropped" or None (none
    pending)."""
    root = Path(root)
    edit = root / EDIT_DIR
    if not edit.is_dir():
        return None
    marker = edit / COMMIT
    if not marker.is_file():
        shutil.rmtree(edit, ignore_errors=True)
        return "dropped"
    try:
        info = json.loads(marker.read_bytes())
        stage, files = edit / str(info["stage"]), [(str(k), str(n)) for k, n in info["files"]]
    except (OSError, ValueError, KeyError, TypeError):
        raise TerrabenchError(
            f"{root}: tile store's commit marker {marker} is unreadable; an edit was interrupted "
            "while committing: restore the store from its input (terrabench prepare)"
        ) from None
    _finish(root, stage, files)
    return "finished"
