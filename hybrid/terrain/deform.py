"""Procedural deformations driven by time: a travelling wave and a slow uplift, their checks and CPU reference.

A deformation has a centre (world metres, x east and y north, the terrain's frame) and a radius (m), weighted by
the brushes' smooth falloff ``w = (1 - d²/r²)²`` inside the radius, and runs from a start to an end time (seconds
on the editor's clock). At clock time t it reads its own time tau = clamp(t - start, 0, end - start), so after
its end it keeps its last displacement:

- ``Wave(centre, radius, amplitude, wavelength, speed)``: ripples travelling out from the centre, their front at
  d = speed * tau: ``amplitude * w * sin(2 pi frac((d - speed tau) / wavelength))`` behind the front, 0 beyond;
- ``Uplift(centre, radius, rate)``: ``rate * tau * w`` (m/s; negative: subsidence).

The terrain at time t is a function of (base, deformations, t), never of the frames before: heights = base + each
deformation's displacement, in the order they were added, where the base is the terrain with every brush applied
(brushes edit the ground under the deformations). Everything is float32 over the samples a deformation touches
(``touched``), in the GPU pass's (``hybrid.gl.deform``) order of operations; the GPU's sine differs from NumPy's in
the last bits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.edits import BrushParams, Window, _finite, check_disc, touched
from hybrid.terrain.heightfield import MAX_ABS_HEIGHT, HeightField

DEFORMATIONS = {"wave": 0, "uplift": 1}
"""Deformation names (as the edit log writes them) and the GPU pass's codes."""
MAX_SECONDS = 86400.0  # latest end time (s): float32 times keep steps of 8 ms or finer within it
TWO_PI = np.float32(2.0 * np.pi)


@dataclass(frozen=True)
class Wave:
    """Ripples of ``amplitude`` metres and ``wavelength`` metres travelling out from the centre at ``speed`` m/s,
    within ``radius`` metres, with the brushes' falloff."""

    centre: tuple[float, float]
    radius: float
    amplitude: float
    wavelength: float
    speed: float
    kind = "wave"


@dataclass(frozen=True)
class Uplift:
    """The ground within ``radius`` metres of the centre rising at ``rate`` m/s at the centre (negative: sinking),
    with the brushes' falloff."""

    centre: tuple[float, float]
    radius: float
    rate: float
    kind = "uplift"


Deformation = Wave | Uplift
DEFORMATION_TYPES: dict[str, type] = {"wave": Wave, "uplift": Uplift}


@dataclass(frozen=True)
class DeformParams:
    """A deformation in the grid's texel space: code (``DEFORMATIONS``), its disc (``BrushParams``: centre in
    fractional samples, spacing, radius), amplitude (m; an uplift's rate, m/s), wavelength (m), speed (m/s), and
    its start and end (s on the editor's clock)."""

    code: int
    disc: BrushParams
    amplitude: float
    wavelength: float
    speed: float
    start: float
    end: float

    def tau(self, t: float) -> float:
        """The deformation's own time (s, float32) at clock time t: clamped to [0, end - start]."""
        return float(np.float32(min(max(float(t) - self.start, 0.0), self.end - self.start)))


def check_deformation(d: Deformation, hf: HeightField, start: float, end: float) -> Deformation:
    """The deformation if it fits the terrain and its times, else a TerrabenchError naming what is wrong: centre on
    the terrain, 0 < radius <= its larger extent, finite values (wavelength and speed > 0, displacement within
    ±MAX_ABS_HEIGHT m), 0 <= start < end <= MAX_SECONDS (s)."""
    if not isinstance(d, (Wave, Uplift)):
        raise TerrabenchError(f"a deformation must be one of {', '.join(DEFORMATIONS)}, got {type(d).__name__}")
    name = f"{d.kind} deformation"
    check_disc(name, d.centre, d.radius, hf)
    t0, t1 = _finite(f"{name} start", start), _finite(f"{name} end", end)
    if not 0.0 <= t0 < t1 <= MAX_SECONDS:
        raise TerrabenchError(
            f"{name} start and end must satisfy 0 <= start < end <= {MAX_SECONDS:g} s, got "
            f"start {start!r} and end {end!r}"
        )
    if isinstance(d, Wave):
        a = _finite(f"{name} amplitude", d.amplitude)
        for k in ("wavelength", "speed"):
            if not _finite(f"{name} {k}", getattr(d, k)) > 0.0:
                raise TerrabenchError(f"{name} {k} must be > 0, got {getattr(d, k)!r}")
    else:
        a = _finite(f"{name} rate", d.rate) * (t1 - t0)
    if abs(a) > MAX_ABS_HEIGHT:
        raise TerrabenchError(f"{name} displacement {a:g} m lies beyond ±{MAX_ABS_HEIGHT:g} m")
    return d


def deform_params(d: Deformation, hf: HeightField, start: float, end: float) -> DeformParams:
    """The checked deformation in hf's texel space (``DeformParams``)."""
    check_deformation(d, hf, start, end)
    ox, oy, _ = hf.origin
    disc = BrushParams(
        -1,
        (float(d.centre[1]) - oy) / hf.spacing_y,
        (float(d.centre[0]) - ox) / hf.spacing_x,
        hf.spacing_x,
        hf.spacing_y,
        float(d.radius),
        0.0,
        0.0,
    )
    if isinstance(d, Wave):
        return DeformParams(
            DEFORMATIONS["wave"],
            disc,
            float(d.amplitude),
            float(d.wavelength),
            float(d.speed),
            float(start),
            float(end),
        )
    return DeformParams(DEFORMATIONS["uplift"], disc, float(d.rate), 0.0, 0.0, float(start), float(end))


def deform_window(p: DeformParams, rows: int, cols: int) -> Window:
    """The samples a deformation can change: within its radius of the centre, clipped to the grid."""
    return touched(p.disc, rows, cols)


def displacement(p: DeformParams, win: Window, t: float) -> np.ndarray:
    """float32 displacement (metres) of a deformation at clock time t (s) over a window of samples."""
    f32, q = np.float32, p.disc
    i = np.arange(win.i0, win.i1, dtype=np.float32)[:, None]
    j = np.arange(win.j0, win.j1, dtype=np.float32)[None, :]
    dy, dx = (i - f32(q.ci)) * f32(q.sy), (j - f32(q.cj)) * f32(q.sx)
    d2 = dx * dx + dy * dy
    t2 = d2 / f32(q.radius * q.radius)
    w = (f32(1.0) - t2) * (f32(1.0) - t2)
    tau = f32(p.tau(t))
    if p.code == DEFORMATIONS["uplift"]:
        return np.where(t2 < f32(1.0), f32(p.amplitude) * tau * w, f32(0.0)).astype(np.float32)
    d = np.sqrt(d2)
    front = f32(p.speed) * tau
    phase = (d - front) / f32(p.wavelength)
    phase = phase - np.floor(phase)
    v = f32(p.amplitude) * w * np.sin(TWO_PI * phase)
    return np.where((t2 < f32(1.0)) & (d < front), v, f32(0.0)).astype(np.float32)


def compose(base: np.ndarray, params: list[DeformParams], t: float, win: Window) -> np.ndarray:
    """float32 heights (metres, relative to the origin z) over a window at clock time t (s): the base plus each
    deformation's displacement, in order (the CPU reference of the GPU's composition)."""
    h = base[win.slices()].astype(np.float32)
    for p in params:
        h = h + displacement(p, win, t)
    return h
