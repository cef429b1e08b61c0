"""Terrain edits: brushes that change heights around a centre, checked against a terrain, and their CPU reference.

A brush has a centre (world metres, x east and y north, in the terrain's frame: origin included), a radius (m) and
a strength. Its weight at a sample at ground distance d from the centre is the smooth falloff
w = (1 - d²/r²)² for d < r, else 0 (continuous slope at the rim), so an edit never leaves a step at its edge:

- ``Raise``: h += strength * w (metres; negative lowers);
- ``Flatten``: h += (height - h) * strength * w, ``height`` a world z in metres, strength in [0, 1];
- ``Smooth``: h += (mean of the 3x3 samples around - h) * strength * w, strength in [0, 1], reading the heights
  before the edit (neighbours clamped at the grid's edge);
- ``Crater``: an impact of depth ``strength`` (m): a bowl inside 0.7 r and a raised rim around it.

Every brush is computed in float32 over the samples it touches only (``touched``); ``brush_params`` turns a brush
into the texel-space numbers the CPU (``apply_brush``) and the GPU pass (``hybrid.gl.brush``) both compute from.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import MAX_ABS_HEIGHT, HeightField

KINDS = {"raise": 0, "flatten": 1, "smooth": 2, "crater": 3}
"""Brush names (as the edit log writes them) and the GPU pass's codes."""
CRATER_BOWL = 0.7  # share of the radius the crater's bowl spans
CRATER_RIM = 0.3  # the rim's height as a share of the crater's depth


@dataclass(frozen=True)
class Raise:
    """Raise (strength > 0) or lower (< 0) by ``strength`` metres at the centre, with the smooth falloff."""

    centre: tuple[float, float]
    radius: float
    strength: float
    kind = "raise"


@dataclass(frozen=True)
class Flatten:
    """Pull heights toward world z ``height`` (metres) by ``strength`` in [0, 1] at the centre, with the falloff."""

    centre: tuple[float, float]
    radius: float
    strength: float
    height: float
    kind = "flatten"


@dataclass(frozen=True)
class Smooth:
    """Pull heights toward their 3x3 mean by ``strength`` in [0, 1] at the centre, with the falloff."""

    centre: tuple[float, float]
    radius: float
    strength: float
    kind = "smooth"


@dataclass(frozen=True)
class Crater:
    """An impact: a bowl ``strength`` metres deep at the centre and a rim around it, out to ``radius``."""

    centre: tuple[float, float]
    radius: float
    strength: float
    kind = "crater"


Brush = Raise | Flatten | Smooth | Crater
BRUSHES: dict[str, type] = {"raise": Raise, "flatten": Flatten, "smooth": Smooth, "crater": Crater}


@dataclass(frozen=True)
class Window:
    """Sample rows [i0, i1) and columns [j0, j1) of a grid (rows south to north); empty when i0 >= i1 or j0 >= j1."""

    i0: int
    i1: int
    j0: int
    j1: int

    @property
    def empty(self) -> bool:
        """True when the window holds no sample."""
        return self.i0 >= self.i1 or self.j0 >= self.j1

    def union(self, other: Window) -> Window:
        """The smallest window holding both (an empty one adds nothing)."""
        if self.empty:
            return other
        if other.empty:
            return self
        return Window(min(self.i0, other.i0), max(self.i1, other.i1), min(self.j0, other.j0), max(self.j1, other.j1))

    def slices(self) -> tuple[slice, slice]:
        """(rows, columns) slices of the window."""
        return slice(self.i0, self.i1), slice(self.j0, self.j1)

    def intersection(self, other: Window) -> Window:
        """The samples both windows hold (empty where they share none)."""
        return Window(max(self.i0, other.i0), min(self.i1, other.i1), max(self.j0, other.j0), min(self.j1, other.j1))

    def grown(self, k: int, rows: int, cols: int) -> Window:
        """The window grown by k samples on every side, clipped to a (rows, cols) grid."""
        return Window(max(self.i0 - k, 0), min(self.i1 + k, rows), max(self.j0 - k, 0), min(self.j1 + k, cols))


@dataclass(frozen=True)
class BrushParams:
    """A brush in the grid's texel space: code (``KINDS``), centre (ci row, cj column, fractional), spacing (sx, sy,
    metres), radius (m), strength and target (metres relative to the origin z; flatten only)."""

    code: int
    ci: float
    cj: float
    sx: float
    sy: float
    radius: float
    strength: float
    target: float


def _finite(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TerrabenchError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(v):
        raise TerrabenchError(f"{name} must be finite, got {value!r}")
    return v


def check_disc(name: str, centre, radius, hf) -> tuple[float, float, float]:
    """(x, y, radius) metres of a disc on the terrain (centre an (x, y) pair on it in its world frame, 0 < radius
    <= its larger extent), else a TerrabenchError naming ``name`` and what is wrong."""
    try:
        cx, cy = (_finite(f"{name} centre {a}", v) for a, v in zip("xy", centre, strict=True))
    except (TypeError, ValueError):
        raise TerrabenchError(f"{name} centre must be an (x, y) pair of metres, got {centre!r}") from None
    ox, oy, _ = hf.origin
    w, d = hf.extent
    if not (ox <= cx <= ox + w and oy <= cy <= oy + d):
        raise TerrabenchError(
            f"{name} centre ({cx:g}, {cy:g}) m lies off terrain {hf.name!r}, which spans x "
            f"{ox:g} .. {ox + w:g} and y {oy:g} .. {oy + d:g} m"
        )
    r = _finite(f"{name} radius", radius)
    if not (0.0 < r <= max(w, d)):
        raise TerrabenchError(
            f"{name} radius must lie in (0, {max(w, d):g}] m (the terrain's larger extent), got {radius!r}"
        )
    return cx, cy, r


def check_brush(brush: Brush, hf: HeightField) -> Brush:
    """The brush if it fits the terrain (centre on it, 0 < radius <= its larger extent, finite strength in range),
    else a TerrabenchError naming what is wrong; metres in the terrain's world frame."""
    if not isinstance(brush, (Raise, Flatten, Smooth, Crater)):
        raise TerrabenchError(f"an edit must be one of {', '.join(BRUSHES)}, got {type(brush).__name__}")
    name = f"{brush.kind} brush"
    check_disc(name, brush.centre, brush.radius, hf)
    s = _finite(f"{name} strength", brush.strength)
    if brush.kind in ("flatten", "smooth") and not 0.0 <= s <= 1.0:
        raise TerrabenchError(f"{name} strength must lie in [0, 1], got {brush.strength!r}")
    if abs(s) > MAX_ABS_HEIGHT:
        raise TerrabenchError(f"{name} strength must lie within ±{MAX_ABS_HEIGHT:g} m, got {brush.strength!r}")
    if isinstance(brush, Flatten):
        z = _finite(f"{name} height", brush.height)
        if abs(z - hf.origin[2]) > MAX_ABS_HEIGHT:
            raise TerrabenchError(f"{name} height {z:g} m lies beyond ±{MAX_ABS_HEIGHT:g} m of the terrain's origin")
    return brush


def brush_params(brush: Brush, hf: HeightField) -> BrushParams:
    """The checked brush in hf's texel space (``BrushParams``): centre in fractional samples, target relative to
    the origin z."""
    check_brush(brush, hf)
    ox, oy, oz = hf.origin
    target = float(brush.height) - oz if isinstance(brush, Flatten) else 0.0
    return BrushParams(
        KINDS[brush.kind],
        (float(brush.centre[1]) - oy) / hf.spacing_y,
        (float(brush.centre[0]) - ox) / hf.spacing_x,
        hf.spacing_x,
        hf.spacing_y,
        float(brush.radius),
        float(brush.strength),
        target,
    )


def touched(p: BrushParams, rows: int, cols: int) -> Window:
    """The samples a brush can change (weight > 0): within its radius of the centre, clipped to the grid."""
    ri, rj = p.radius / p.sy, p.radius / p.sx
    i0, i1 = max(int(np.ceil(p.ci - ri)), 0), min(int(np.floor(p.ci + ri)) + 1, rows)
    j0, j1 = max(int(np.ceil(p.cj - rj)), 0), min(int(np.floor(p.cj + rj)) + 1, cols)
    return Window(i0, max(i1, i0), j0, max(j1, j0))


def _mean3(h: np.ndarray, win: Window) -> np.ndarray:
    """float32 mean of the 3x3 samples around each sample of the window (clamped at the grid's edge)."""
    rows = np.clip(np.arange(win.i0 - 1, win.i1 + 1), 0, h.shape[0] - 1)
    cols = np.clip(np.arange(win.j0 - 1, win.j1 + 1), 0, h.shape[1] - 1)
    a = h[np.ix_(rows, cols)].astype(np.float32)
    total = np.zeros((win.i1 - win.i0, win.j1 - win.j0), np.float32)
    for di in range(3):  # row by row, in the GPU pass's order of summation
        for dj in range(3):
            total += a[di : di + total.shape[0], dj : dj + total.shape[1]]
    return total / np.float32(9.0)


def brush_delta(p: BrushParams, h: np.ndarray, win: Window) -> np.ndarray:
    """float32 new heights (metres, relative to origin z) of window ``win`` of heights h after brush p."""
    f32 = np.float32
    i = np.arange(win.i0, win.i1, dtype=np.float32)[:, None]
    j = np.arange(win.j0, win.j1, dtype=np.float32)[None, :]
    dy, dx = (i - f32(p.ci)) * f32(p.sy), (j - f32(p.cj)) * f32(p.sx)
    t = (dx * dx + dy * dy) / f32(p.radius * p.radius)
    inside = t < f32(1.0)
    w = np.where(inside, (f32(1.0) - t) * (f32(1.0) - t), f32(0.0)).astype(np.float32)
    old = h[win.slices()].astype(np.float32)
    s = f32(p.strength)
    if p.code == KINDS["raise"]:
        new = old + s * w
    elif p.code == KINDS["flatten"]:
        new = old + (f32(p.target) - old) * (s * w)
    elif p.code == KINDS["smooth"]:
        new = old + (_mean3(h, win) - old) * (s * w)
    else:
        new = old + _crater(np.sqrt(t), s)
    return np.where(inside, new, old).astype(np.float32)


def _crater(q: np.ndarray, depth: np.float32) -> np.ndarray:
    """float32 change (metres) of a crater of ``depth`` at distance q (share of the radius): bowl and rim."""
    f32 = np.float32
    a, rim = f32(CRATER_BOWL), f32(1.0 - CRATER_BOWL)
    b = f32(1.0) - (q * q) / (a * a)
    bowl = np.where(q < a, -depth * b, f32(0.0))
    u = (q - a) / rim
    c = f32(1.0) - u * u
    ring = np.where(np.abs(q - a) < rim, f32(CRATER_RIM) * depth * c * c, f32(0.0))
    return (bowl + ring).astype(np.float32)


def apply_brush(heights: np.ndarray, p: BrushParams) -> Window:
    """Apply brush p to float32 heights (metres, rows south to north) in place over the touched window only;
    returns that window (empty: nothing changed)."""
    win = touched(p, heights.shape[0], heights.shape[1])
    if not win.empty:
        heights[win.slices()] = brush_delta(p, heights, win)
    return win
