"""Progress of long runs: one line on a terminal, one line per 10 % in a log file."""

from __future__ import annotations

import sys
import time

import numpy as np


class Progress:
    """A one-line progress bar with the time left, on stderr."""

    def __init__(self, total: int, done: int, enabled: bool = True):
        self.total, self.done, self.enabled = total, done, enabled
        self.start, self.start_done = time.perf_counter(), done
        self.tty = sys.stderr.isatty()
        self.last_decile = -1

    def step(self, label: str) -> None:
        """Count one unit of work finished and redraw."""
        self.done += 1
        if not self.enabled:
            return
        el = time.perf_counter() - self.start
        rate = (self.done - self.start_done) / el if el > 0 else 0
        left = (self.total - self.done) / rate if rate > 0 else float("nan")
        frac = self.done / max(self.total, 1)
        bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
        eta = f"{int(left // 60)}m{int(left % 60):02d}s" if np.isfinite(left) else "?"
        line = f"[{bar}] {self.done}/{self.total} {100 * frac:5.1f} % left {eta}  {label[:60]:60s}"
        if self.tty:
            sys.stderr.write("\r" + line)
        elif int(10 * frac) != self.last_decile:  # a log file gets one line per 10 %
            self.last_decile = int(10 * frac)
            sys.stderr.write(line.rstrip() + "\n")
        sys.stderr.flush()

    def close(self) -> None:
        """End the line."""
        if self.enabled and self.tty:
            sys.stderr.write("\n")
