"""argparse ``type=`` checks shared by the subcommands, each built by one factory that names the option.

A failed check raises TerrabenchError naming the option, the value and the accepted range. argparse turns
only ArgumentTypeError, TypeError and ValueError into its own usage error (SystemExit); a TerrabenchError
passes through ``parse_args`` to ``main()``, which prints it as the one line ``terrabench: error: ...`` and
returns 2, the same as every other user error, before anything is written.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from hybrid.errors import TerrabenchError, check_positive
from hybrid.terrain.window import Crop


def positive_float(option: str, unit: str = "") -> Callable[[str], float]:
    """A check for a finite number > 0; unit (e.g. 'pixels') is named in the message."""
    name = f"{option} ({unit})" if unit else option
    # check_positive parses the text itself, so a non-number gets the same message; it is annotated as float
    return lambda text: check_positive(name, text)  # type: ignore[arg-type]


def int_in(option: str, lo: int, hi: int) -> Callable[[str], int]:
    """A check for an integer in [lo, hi]."""

    def check(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            v = None
        if v is None or not (lo <= v <= hi):
            raise TerrabenchError(f"{option} must be an integer in [{lo}, {hi}], got {text!r}")
        return v

    return check


def power_of_two(option: str, lo: int = 2, hi: int = 4096) -> Callable[[str], int]:
    """A check for a power of two in [lo, hi] cells (tile sizes)."""

    def check(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            n = 0
        if not (lo <= n <= hi) or n & (n - 1):
            raise TerrabenchError(f"{option} must be a power of two in [{lo}, {hi}] cells, got {text!r}")
        return n

    return check


def size(option: str) -> Callable[[str], tuple[int, int]]:
    """A check for WIDTHxHEIGHT in pixels, giving (width, height)."""
    from hybrid.camera.view import parse_size

    return lambda text: parse_size(text, option)


def sizes(option: str) -> Callable[[str], list[str]]:
    """A check for a comma-separated list of WIDTHxHEIGHT pixel sizes, giving the sizes as written."""
    from hybrid.camera.view import parse_size

    split = words(option)

    def check(text: str) -> list[str]:
        out = split(text)
        for s in out:
            parse_size(s, option)
        return out

    return check


def rows_cols(option: str) -> Callable[[str], tuple[int, int]]:
    """A check for ROWSxCOLS (raw file shapes), giving (rows, cols)."""

    def check(text: str) -> tuple[int, int]:
        try:
            rows, cols = (int(s) for s in text.lower().split("x"))
        except ValueError:
            raise TerrabenchError(f"{option} must be ROWSxCOLS, got {text!r}") from None
        return rows, cols

    return check


def spacing(option: str) -> Callable[[str], float | tuple[float, float]]:
    """A check for a ground spacing in metres: one number, or X,Y (east-west, north-south), each finite and > 0."""

    def check(text: str) -> float | tuple[float, float]:
        parts = text.split(",")
        if len(parts) not in (1, 2):
            raise TerrabenchError(f"{option} must be one number or X,Y (metres east-west, north-south), got {text!r}")
        # check_positive parses each text (see positive_float)
        values = [check_positive(f"{option} (metres)", p.strip()) for p in parts]  # type: ignore[arg-type]
        return values[0] if len(values) == 1 else (values[0], values[1])

    return check


def crop(option: str) -> Callable[[str], Crop]:
    """A check for a crop window ROW,COL,ROWS,COLS in samples, rows as stored in the file, giving a Crop."""
    return lambda text: Crop.parse(text, option)


def vec3(option: str) -> Callable[[str], np.ndarray]:
    """A check for three numbers x,y,z in metres, giving a float64 array."""

    def check(text: str) -> np.ndarray:
        try:
            v = [float(s) for s in text.split(",")]
        except ValueError:
            v = []
        if len(v) != 3:
            raise TerrabenchError(f"{option} must be three numbers x,y,z in metres, got {text!r}")
        return np.array(v)

    return check


def words(option: str) -> Callable[[str], list[str]]:
    """A check for a non-empty comma-separated list, giving the stripped words."""

    def check(text: str) -> list[str]:
        out = [t.strip() for t in text.split(",") if t.strip()]
        if not out:
            raise TerrabenchError(f"{option} must name at least one, got {text!r}")
        return out

    return check


def names(option: str, allowed: Iterable[str]) -> Callable[[str], list[str]]:
    """A check for a comma-separated list of names from a fixed set."""
    allowed = tuple(allowed)
    split = words(option)

    def check(text: str) -> list[str]:
        bad = [n for n in split(text) if n not in allowed]
        if bad:
            raise TerrabenchError(f"{option}: unknown {bad}; choose from {', '.join(allowed)}")
        return split(text)

    return check
