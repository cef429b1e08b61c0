"""Why a path names nothing readable: missing, a broken symlink or a symlink loop."""

from __future__ import annotations

import errno
import os


def path_problem(path) -> str | None:
    """Why ``path`` names nothing that can be read ('no such file', a symlink loop, a broken symlink), or None."""
    try:
        os.stat(path)
    except FileNotFoundError:
        if os.path.islink(path):
            return f"a broken symlink (to {os.readlink(path)}, which does not exist)"
        return "no such file"
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return "a symlink loop (its links never reach a file)"
        return exc.strerror or str(exc)
    return None
