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


def read_json(path, what: str):
    """The JSON document at path; a missing, unreadable or corrupt file is a TerrabenchError naming it."""
    import json

    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise TerrabenchError(f"{what} {path} is missing") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise TerrabenchError(f"{what} {path} is corrupt: not readable JSON ({_first_line(exc)})") from None


def read_parquet(path, what: str):
    """The Parquet table at path as a DataFrame; a missing, unreadable or corrupt file is a TerrabenchError."""
    import pandas as pd

    path = Path(path)
    try:
        return pd.read_parquet(path)
    except FileNotFoundError:
        raise TerrabenchError(f"{what} {path} is missing") from None
    except (OSError, ValueError) as exc:  # pyarrow's ArrowInvalid is a ValueError
        raise TerrabenchError(f"{what} {path} is corrupt: not a readable Parquet table ({_first_line(exc)})") from None


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__
