"""Output folders: made if needed and proved writable before anything is computed or written."""
from __future__ import annotations

import tempfile
from pathlib import Path

from hybrid.errors import TerrabenchError


def writable_folder(path, what: str) -> Path:
    """Create the folder if needed and prove it writable with a probe file; else a TerrabenchError naming it."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".terrabench-probe-"):
            pass
    except OSError as exc:
        raise TerrabenchError(f"{what} {path} is not a writable folder ({exc.strerror or exc})") from None
    return path
