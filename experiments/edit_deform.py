"""The procedural deformation an edit spec's programme may name (``[edit.deformation]``), replayed alike by every
editing configuration and its reference::

    [edit.deformation]                # optional: a deformation driven by time (hybrid.terrain.deform)
    kind = "wave"                     # wave or uplift
    centre = [0.5, 0.5]               # in the programme's units (fractions of the extent, or world metres)
    radius = 6000.0                   # metres
    amplitude = 150.0                 # wave: ripple height (m), wavelength (m) and speed (m/s)
    wavelength = 3000.0
    speed = 1500.0
    # rate = 40.0                     # uplift instead: metres a second at the centre (negative: sinking)
    start = 0.0                       # seconds on the editor's clock it runs from and to
    end = 10.0
    seconds_per_frame = 1.0           # clock seconds a frame: frame k is drawn at (k + 1) * seconds_per_frame

Every editing configuration adds it before its first frame; before each frame's draw, after the frame's brushes,
the GPU heights are set to the frame's clock time and written through (``TerrainEditor.step`` and ``sync``), so
every renderer follows it as it follows a brush. The heights at a time depend on the time only (base plus the
displacement), so a run's edit log replays its last frame's terrain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hybrid.errors import TerrabenchError
from hybrid.terrain.deform import DEFORMATION_TYPES, MAX_SECONDS, Deformation, Uplift, Wave, check_deformation
from hybrid.terrain.heightfield import HeightField

KIND_KEYS = {"wave": ("amplitude", "wavelength", "speed"), "uplift": ("rate",)}
"""The keys each kind of deformation takes besides the common ones."""
COMMON_KEYS = ("kind", "centre", "radius", "start", "end", "seconds_per_frame")


@dataclass(frozen=True)
class DeformProgramme:
    """A deformation of an edit programme: its kind, centre (in the programme's units), radius (m), the values its
    kind takes (``KIND_KEYS``; None for the other kind's), start and end (s on the editor's clock), and clock
    seconds a frame."""

    kind: str
    centre: tuple[float, float]
    radius: float
    amplitude: float | None = None
    wavelength: float | None = None
    speed: float | None = None
    rate: float | None = None
    start: float = 0.0
    end: float = 10.0
    seconds_per_frame: float = 1.0

    def time(self, frame: int) -> float:
        """The clock time (s) frame ``frame`` is drawn at."""
        return (frame + 1) * self.seconds_per_frame


def _number(d: dict, key: str, where: str) -> float:
    """d[key], a finite number, else a TerrabenchError naming the key and value."""
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise TerrabenchError(f"{where}: '{key}' must be a finite number, got {v!r}")
    return float(v)


def _positive(d: dict, key: str, where: str) -> float:
    v = _number(d, key, where)
    if v <= 0:
        raise TerrabenchError(f"{where}: '{key}' must be > 0, got {d[key]!r}")
    return v


def _centre(v, units: str, where: str) -> tuple[float, float]:
    """The centre, checked: a pair of finite numbers, fractions in [0, 1]."""
    if not isinstance(v, list) or len(v) != 2:
        raise TerrabenchError(f"{where}: 'centre' must be [x, y], got {v!r}")
    x, y = (_number({"centre": c}, "centre", where) for c in v)
    if units == "fraction" and not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0):
        raise TerrabenchError(
            f"{where}: 'centre' ({x:g}, {y:g}) lies off the terrain: as fractions of the extent "
            '(units = "fraction") x and y must lie in [0, 1]'
        )
    return x, y


def parse_deformation(d, units: str, source: str) -> DeformProgramme:
    """The [edit.deformation] table checked by name: a known kind with exactly its keys, finite values, radius,
    wavelength, speed and seconds a frame > 0, 0 <= start < end <= MAX_SECONDS."""
    where = f"{source}: [edit.deformation]"
    if not isinstance(d, dict):
        raise TerrabenchError(f"{source}: [edit] 'deformation' must be a table (kind, centre, radius, ...), got {d!r}")
    kind = d.get("kind")
    if kind not in KIND_KEYS:
        raise TerrabenchError(f"{where}: 'kind' must be one of {', '.join(KIND_KEYS)}, got {kind!r}")
    known = set(COMMON_KEYS) | set(KIND_KEYS[kind])
    unknown = sorted(set(d) - known)
    if unknown:
        raise TerrabenchError(f"{where}: unknown keys {unknown} for kind = {kind!r}; known: {sorted(known)}")
    missing = [k for k in ("centre", "radius", *KIND_KEYS[kind]) if k not in d]
    if missing:
        raise TerrabenchError(f"{where}: a {kind} needs {missing}")
    values = {
        k: _positive(d, k, where) if k in ("wavelength", "speed") else _number(d, k, where) for k in KIND_KEYS[kind]
    }
    times = {k: _number(d, k, where) for k in ("start", "end") if k in d}
    start, end = times.get("start", DeformProgramme.start), times.get("end", DeformProgramme.end)
    if not 0.0 <= start < end <= MAX_SECONDS:
        raise TerrabenchError(
            f"{where}: 'start' and 'end' must satisfy 0 <= start < end <= {MAX_SECONDS:g} s, got start {start!r} "
            f"and end {end!r}"
        )
    spf = _positive(d, "seconds_per_frame", where) if "seconds_per_frame" in d else DeformProgramme.seconds_per_frame
    radius = _positive(d, "radius", where)
    return DeformProgramme(
        kind, _centre(d["centre"], units, where), radius, **values, start=start, end=end, seconds_per_frame=spf
    )


def deformation(p: DeformProgramme, units: str, hf: HeightField, spec_name: str) -> Deformation:
    """The deformation in world metres (hf's frame), checked against the terrain: a TerrabenchError naming the spec
    and what does not fit (a centre off it, a radius beyond its extent, a displacement out of range)."""
    cx, cy = p.centre
    if units == "fraction":
        (ox, oy, _), (w, h) = hf.origin, hf.extent
        cx, cy = ox + cx * w, oy + cy * h
    d = DEFORMATION_TYPES[p.kind]((float(cx), float(cy)), p.radius, *(getattr(p, k) for k in KIND_KEYS[p.kind]))
    assert isinstance(d, (Wave, Uplift))
    try:
        return check_deformation(d, hf, p.start, p.end)
    except TerrabenchError as exc:
        raise TerrabenchError(f"spec {spec_name!r} [edit.deformation]: {exc}") from None
