"""Output files that land whole or not at all: written under a temporary name beside the target, then renamed.

A failure while writing (disk full, a killed process, an exception in the writer) leaves the target as it was
(absent or the previous version) and no partial file; a full disk or another OS error becomes one
TerrabenchError naming the file.
"""

from __future__ import annotations

import errno
import json
import os
import re
from contextlib import contextmanager, suppress
from pathlib import Path

from hybrid.errors import TerrabenchError


@contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path beside ``path`` (same suffix, for writers that choose a format by it); on success
    it is renamed onto ``path``, on any failure removed. OS errors become a TerrabenchError naming ``path``."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp{suffix if suffix is not None else path.suffix}")
    try:
        yield tmp
        with open(tmp, "rb+") as f:  # the bytes are on disk before the name points at them
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        _remove(tmp)
        if disk_full(exc) and exc.errno is None:  # a short write: no errno to tell the two apart
            raise TerrabenchError(
                f"cannot write {path}: disk full or a file size limit reached ({exc}); nothing was written there"
            ) from None
        if disk_full(exc):
            raise TerrabenchError(f"disk full while writing {path}; nothing was written there") from None
        raise TerrabenchError(f"cannot write {path}: {exc.strerror or exc}") from None
    except BaseException:
        _remove(tmp)
        raise


_TEMP = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.tmp(?P<suffix>\.[^.]+)?$")


def _alive(pid: int) -> bool:
    """Whether a process of this id runs on this machine (one of another user's counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (OverflowError, OSError):
        return False
    return True


def remove_stale_temps(folder) -> list[Path]:
    """Remove the temporaries atomic_path left in folder (not below it) for writers that are gone: names
    ``.NAME.PID.tmpSUFFIX`` whose PID runs no process here. A live writer's temporary is kept. Returns those
    removed."""
    removed: list = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for e in entries:
        m = _TEMP.match(e.name)
        if m is None or not e.is_file(follow_symlinks=False) or _alive(int(m["pid"])):
            continue
        try:
            os.unlink(e.path)
            removed.append(Path(e.path))
        except FileNotFoundError:
            pass
    return removed


def disk_full(exc: OSError) -> bool:
    """Whether an OS error from a write means the disk (or the user's quota) is full: ENOSPC or EDQUOT, or the
    short write NumPy reports without an errno ('14400 requested and 10208 written')."""
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return True
    text = str(exc)
    return "No space left on device" in text or ("requested and" in text and "written" in text)


def _remove(p: Path) -> None:
    with suppress(FileNotFoundError):
        p.unlink()


def write_text(path, text: str) -> Path:
    """Write a text file (UTF-8) atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_json(path, data) -> Path:
    """Write indented JSON atomically."""
    return write_text(path, json.dumps(data, indent=1))


def save_npy(path, array) -> Path:
    """Write a NumPy array (.npy) atomically."""
    import numpy as np

    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.save(f, array)
    return Path(path)


def save_png(path, image) -> Path:
    """Write an 8-bit (H, W[, 3|4]) image as PNG atomically."""
    from PIL import Image

    with atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
    return Path(path)


def write_parquet(path, frame) -> Path:
    """Write a pandas DataFrame as Parquet atomically."""
    with atomic_path(path) as tmp:
        frame.to_parquet(tmp, index=False)
    return Path(path)
