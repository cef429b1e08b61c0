"""Error types raised for bad input anywhere in the toolkit (the CLI turns them into exit code 2).

TerrabenchError is not a ValueError on purpose: the CLI prints it as one line, while any other exception
is a bug and keeps its traceback.
"""


class TerrabenchError(Exception):
    """A user-facing error: the message names the argument or file, the value and the accepted range."""


class TerrainLoadError(TerrabenchError):
    """A height-field file that cannot be read or holds no usable terrain."""


class StoreDamagedError(TerrabenchError):
    """A tile store whose files do not match its manifest (missing, short, altered): never a method's refusal."""


class GLContextError(TerrabenchError):
    """No usable OpenGL context: EGL missing, GL too old, or a bad device index."""


def check_positive(name: str, value: float) -> float:
    """Return value as float if it is finite and > 0, else raise TerrabenchError naming it."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TerrabenchError(f"{name} must be a number > 0, got {value!r}") from None
    if not (v > 0.0) or v == float("inf"):
        raise TerrabenchError(f"{name} must be finite and > 0, got {value!r}")
    return v


def check_range(name: str, value: float, lo: float, hi: float, *, lo_open=True, hi_open=True) -> float:
    """Return value as float if it lies in the interval (lo, hi) (open ends by default), else raise."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TerrabenchError(f"{name} must be a number, got {value!r}") from None
    ok_lo = v > lo if lo_open else v >= lo
    ok_hi = v < hi if hi_open else v <= hi
    if not (ok_lo and ok_hi):
        lb = "(" if lo_open else "["
        rb = ")" if hi_open else "]"
        raise TerrabenchError(f"{name} must lie in {lb}{lo}, {hi}{rb}, got {value!r}")
    return v
