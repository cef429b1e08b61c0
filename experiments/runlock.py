"""One writer per run folder: an advisory lock (flock) on ``<run>/.lock`` holding the owner's PID and host.

The kernel drops the lock when its process ends however it ends, so a lock left by a killed run is taken over
without any clean-up; a second live run on the same folder is refused with the holder's PID.
"""

from __future__ import annotations

import fcntl
import os
import socket
from pathlib import Path

from hybrid.errors import TerrabenchError

LOCK_NAME = ".lock"


class RunLock:
    """Context manager: hold the run folder's lock for the duration of a run, or refuse by naming the holder."""

    def __init__(self, folder):
        self.path = Path(folder) / LOCK_NAME
        self._file = None

    def acquire(self) -> RunLock:
        """Take the lock; a TerrabenchError naming the holder's PID and host if another live process holds it."""
        try:
            f = open(self.path, "a+")  # noqa: SIM115 - held open as long as the lock is held
        except OSError as exc:
            raise TerrabenchError(f"cannot open the run lock {self.path}: {exc.strerror or exc}") from None
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            holder = f.read().strip() or "an unknown process"
            f.close()
            raise TerrabenchError(
                f"{self.path.parent} is in use by another run ({holder}); wait for it to end or choose another --name"
            ) from None
        f.seek(0)
        f.truncate()
        f.write(f"pid {os.getpid()} on {socket.gethostname()}\n")
        f.flush()
        self._file = f
        return self

    def release(self) -> None:
        """Let the lock go (the lock file stays; it is empty of meaning without a holder)."""
        if self._file is not None:
            fcntl.flock(self._file.fileno(), fcntl.LOCK_UN)
            self._file.close()
            self._file = None

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
