"""Edit experiments (kind = "edit"): a flight over a terrain that changes, every method following the same edits.

    kind = "edit"
    name = "edit"
    dataset = "puget"                 # a bundled name, a file or a table (as a flights spec's datasets entry),
                                      # held in memory (a tile store is refused: its edits are not written through)
    dataset_size = 0                  # samples a side of synthetic data / crop of puget (0 = as is)
    flight = "flyover"                # a preset or a .json/.csv flight file
    frames = 6
    policies = ["raster", "raster_gs", "raycast", "hybrid"]
    tau = 0.6667
    sizes = ["320x180"]               # one viewport (a list, so that `terrabench run --sizes` replaces it)
    tile_size = 128
    repeats = 3                       # timed draws a frame, at least 3 (median kept)
    supersample = 1                   # the reference's colour supersampling
    flip = true
    adapt = true                      # the hybrid refits its cost model from the frames it draws
    image_frames = [5]

    [edit]                            # the edit programme, replayed identically by every configuration
    brush = "crater"                  # raise, flatten, smooth or crater (hybrid.terrain.edits)
    path = [[0.25, 0.27], [0.85, 0.8]]   # way-points (x, y): the brush moves along them over the run
    units = "fraction"                # way-points as fractions of the extent from the origin, or "metres" (world)
    radii = [1000.0, 2000.0]          # brush radii (m): one configuration per method and radius
    strength = 60.0                   # metres (raise, crater) or a share in [0, 1] (flatten, smooth)
    height = 0.0                      # flatten only: the world z (m) it pulls toward
    edits_per_frame = 1
    particles = 4096                  # particles on the terrain (hybrid.gl.particles); 0: none
    [edit.deformation]                # optional: a wave or uplift driven by time (experiments.edit_deform)

Every method runs once per radius with the programme and once on the static terrain (``editing`` false), the same
views and particles throughout. The edits of a run: ``frames * edits_per_frame`` brushes spaced evenly along the
path by length, the first at its first way-point and the last at its last, ``edits_per_frame`` of them applied
before each frame's draw.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from hybrid.camera.view import parse_size
from hybrid.errors import TerrabenchError
from hybrid.gl.particles import MAX_PARTICLES
from hybrid.terrain.edits import BRUSHES, Brush, Flatten, check_brush
from hybrid.terrain.heightfield import HeightField

from .edit_deform import DeformProgramme, deformation, parse_deformation
from .run_config import EditConfig
from .spec_datasets import check_dataset_entry, dataset_label, terrain_source

EDIT_POLICIES = ("raster", "raster_gs", "raycast", "hybrid", "heuristic", "oracle")
"""Methods that follow edits (hybrid.editing): the reference is what each is measured against."""
UNITS = ("fraction", "metres")
MAX_EDITS_PER_FRAME = 1000


@dataclass(frozen=True)
class EditProgramme:
    """A brush path: way-points (x, y) in ``units``, the brush's kind, radii (m), strength and flatten height (world
    z, m), edits a frame, the particle count, and a deformation driven by time (or None)."""

    path: tuple[tuple[float, float], ...]
    brush: str = "crater"
    units: str = "fraction"
    radii: tuple[float, ...] = (1000.0, 2000.0)
    strength: float = 60.0
    height: float | None = None
    edits_per_frame: int = 1
    particles: int = 4096
    deformation: DeformProgramme | None = None


@dataclass
class EditSpec:
    """A parsed, checked edit experiment (kind = "edit"; the module docstring lists its keys)."""

    name: str
    edit: EditProgramme
    dataset: object = "puget"
    dataset_size: int = 0
    seed: int = 0
    flight: str = "flyover"
    frames: int = 6
    policies: list = field(default_factory=lambda: ["raster", "raster_gs", "raycast", "hybrid"])
    tau: float = 2 / 3
    sizes: list = field(default_factory=lambda: ["320x180"])
    tile_size: int = 128
    repeats: int = 3
    supersample: int = 1
    flip: bool = True
    adapt: bool = True
    image_frames: list = field(default_factory=lambda: [0])

    @property
    def label(self) -> str:
        """The dataset's label in configurations and tables."""
        return dataset_label(self.dataset)

    def configs(self) -> list[EditConfig]:
        """Every method once per radius with the programme and once on the static terrain."""
        out = []
        size = self.sizes[0]
        base = f"{Path(self.label).stem}-s{self.seed}-{Path(self.flight).stem}-{size}-tau{self.tau:.4g}"
        for policy in self.policies:
            for radius in (*self.edit.radii, 0.0):
                editing = radius > 0
                tail = f"r{radius:g}m" if editing else "static"
                out.append(
                    EditConfig(
                        config=f"{base}-{policy}-{tail}",
                        dataset=self.label,
                        seed=self.seed,
                        flight=self.flight,
                        size=size,
                        tau=self.tau,
                        policy=policy,
                        editing=editing,
                        edit_radius=float(radius),
                        brush=self.edit.brush if editing else "none",
                        particles=self.edit.particles,
                    )
                )
        return out

    def terrain(self) -> HeightField:
        """The terrain the spec names, loaded into memory."""
        return terrain_source(self.dataset).load(size=self.dataset_size or None, seed=self.seed)

    def to_dict(self) -> dict:
        """Plain form, with its kind (no deformation key where it names none, as specs before deformations)."""
        d = {"kind": "edit", **asdict(self)}
        if d["edit"]["deformation"] is None:
            del d["edit"]["deformation"]
        return d

    def same_as(self, stored: dict) -> bool:
        """Whether a stored plain form (a run folder's spec.json) is this spec."""
        import json

        return json.loads(json.dumps(self.to_dict())) == stored


TOP_KEYS = {f for f in EditSpec.__dataclass_fields__} | {"kind"}
EDIT_KEYS = set(EditProgramme.__dataclass_fields__)


def _int(d: dict, key: str, lo: int, hi: int, where: str) -> int:
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise TerrabenchError(f"{where}: '{key}' must be an integer in [{lo}, {hi}], got {v!r}")
    return v


def _number(v, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise TerrabenchError(f"{what} must be a finite number, got {v!r}")
    return float(v)


def _path(v, units: str, where: str) -> tuple[tuple[float, float], ...]:
    """The way-points, checked: pairs of finite numbers, fractions in [0, 1]."""
    if not isinstance(v, list) or not v:
        raise TerrabenchError(f"{where}: 'path' must be a non-empty list of [x, y] way-points, got {v!r}")
    out = []
    for k, p in enumerate(v, start=1):
        if not isinstance(p, list) or len(p) != 2:
            raise TerrabenchError(f"{where}: 'path' way-point {k} must be [x, y], got {p!r}")
        x, y = (_number(c, f"{where}: 'path' way-point {k} {a}") for a, c in zip("xy", p))
        if units == "fraction" and not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0):
            raise TerrabenchError(
                f"{where}: 'path' way-point {k} ({x:g}, {y:g}) lies off the terrain: as fractions "
                'of the extent (units = "fraction") x and y must lie in [0, 1]'
            )
        out.append((x, y))
    return tuple(out)


def parse_programme(d, source: str) -> EditProgramme:
    """The [edit] table checked by name: brush, way-points, units, radii > 0, a finite strength, counts >= 0."""
    where = f"{source}: [edit]"
    if not isinstance(d, dict):
        raise TerrabenchError(f"{source}: 'edit' must be a table of the edit programme, got {d!r}")
    unknown = sorted(set(d) - EDIT_KEYS)
    if unknown:
        raise TerrabenchError(f"{where}: unknown keys {unknown}; known: {sorted(EDIT_KEYS)}")
    brush, units = d.get("brush", "crater"), d.get("units", "fraction")
    if brush not in BRUSHES:
        raise TerrabenchError(f"{where}: 'brush' must be one of {', '.join(BRUSHES)}, got {brush!r}")
    if units not in UNITS:
        raise TerrabenchError(f"{where}: 'units' must be one of {', '.join(UNITS)}, got {units!r}")
    if "path" not in d:
        raise TerrabenchError(f"{where}: 'path' (the brush's way-points) is required")
    radii = d.get("radii", list(EditProgramme.radii))
    if not isinstance(radii, list) or not radii:
        raise TerrabenchError(f"{where}: 'radii' must be a non-empty list of metres, got {radii!r}")
    for r in radii:
        if _number(r, f"{where}: 'radii' entry") <= 0:
            raise TerrabenchError(f"{where}: 'radii' must be > 0 m, got {r!r}")
    if len(set(radii)) != len(radii):
        raise TerrabenchError(f"{where}: 'radii' lists a radius more than once, got {radii!r}")
    strength = _number(d.get("strength", EditProgramme.strength), f"{where}: 'strength'")
    if brush in ("flatten", "smooth") and not 0.0 <= strength <= 1.0:
        raise TerrabenchError(f"{where}: a {brush} brush's 'strength' must lie in [0, 1], got {strength!r}")
    if ("height" in d) != (brush == "flatten"):
        raise TerrabenchError(f"{where}: 'height' (world z, m) goes with brush = \"flatten\" and only with it")
    height = _number(d["height"], f"{where}: 'height'") if "height" in d else None
    counts = {
        k: _int(d, k, 0, hi, where)
        for k, hi in (("edits_per_frame", MAX_EDITS_PER_FRAME), ("particles", MAX_PARTICLES))
        if k in d
    }
    deform = parse_deformation(d["deformation"], units, source) if "deformation" in d else None
    return EditProgramme(
        _path(d["path"], units, where),
        brush,
        units,
        tuple(float(r) for r in radii),
        strength,
        height,
        **counts,
        deformation=deform,
    )


def _scalars(d: dict, source: str) -> dict:
    """The spec's top-level keys other than dataset, edit and name, checked."""
    kw: dict = {}
    for key, lo, hi in (
        ("frames", 1, 100000),
        ("repeats", 3, 1000),
        ("tile_size", 2, 65536),
        ("supersample", 1, 8),
        ("dataset_size", 0, 16385),
        ("seed", 0, 2**32 - 1),
    ):
        if key in d:
            kw[key] = _int(d, key, lo, hi, source)
    if kw.get("tile_size", 2) & (kw.get("tile_size", 2) - 1):
        raise TerrabenchError(f"{source}: 'tile_size' must be a power of two, got {kw['tile_size']}")
    for key in ("flip", "adapt"):
        if key in d:
            if not isinstance(d[key], bool):
                raise TerrabenchError(f"{source}: '{key}' must be true or false, got {d[key]!r}")
            kw[key] = d[key]
    if "tau" in d:
        t = _number(d["tau"], f"{source}: 'tau'")
        if not 0 < t < 1e3:
            raise TerrabenchError(f"{source}: 'tau' must lie in (0, 1000) pixels, got {t!r}")
        kw["tau"] = t
    if "flight" in d:
        if not isinstance(d["flight"], str) or not d["flight"]:
            raise TerrabenchError(f"{source}: 'flight' must be a preset name or a flight file, got {d['flight']!r}")
        kw["flight"] = d["flight"]
    return kw


def _lists(d: dict, source: str) -> dict:
    """The policies, sizes and image frames, checked."""
    kw: dict = {}
    if "policies" in d:
        v = d["policies"]
        if not isinstance(v, list) or not v or len(set(map(str, v))) != len(v):
            raise TerrabenchError(f"{source}: 'policies' must be a non-empty list, each once, got {v!r}")
        bad = [p for p in v if p not in EDIT_POLICIES]
        if bad:
            raise TerrabenchError(
                f"{source}: policies {bad} do not follow edits; choose from {', '.join(EDIT_POLICIES)}"
            )
        kw["policies"] = v
    if "sizes" in d:
        v = d["sizes"]
        if not isinstance(v, list) or len(v) != 1:
            raise TerrabenchError(f"{source}: an edit spec takes one viewport, 'sizes' = [\"WxH\"], got {v!r}")
        parse_size(v[0], f"{source}: size")
        kw["sizes"] = [str(v[0])]
    if "image_frames" in d:
        v = d["image_frames"]
        if not isinstance(v, list) or not all(isinstance(x, int) and not isinstance(x, bool) for x in v):
            raise TerrabenchError(f"{source}: 'image_frames' must be a list of frame numbers, got {v!r}")
        kw["image_frames"] = v
    return kw


def parse_edit_spec(d: dict, source: str, base: Path | None = None) -> EditSpec:
    """Check a kind = "edit" spec (its keys less ``kind``): every value by name, before anything runs."""
    unknown = sorted(set(d) - TOP_KEYS)
    if unknown:
        raise TerrabenchError(f"{source}: unknown keys {unknown}; known: {sorted(TOP_KEYS - {'kind'})}")
    name = d.get("name", Path(source).stem)
    if not isinstance(name, str) or not name or any(c in name for c in "/\\ "):
        raise TerrabenchError(f"{source}: name must be a non-empty word without slashes or spaces, got {name!r}")
    if "edit" not in d:
        raise TerrabenchError(f"{source}: an edit spec needs its [edit] table (the brush path)")
    kw = {"name": name, "edit": parse_programme(d["edit"], source), **_scalars(d, source), **_lists(d, source)}
    if "dataset" in d:
        kw["dataset"] = check_dataset_entry(d["dataset"], source, base)
        if "@periodic" in str(kw["dataset"] if isinstance(kw["dataset"], str) else kw["dataset"]["path"]):
            raise TerrabenchError(
                f"{source}: an edit spec's dataset is held in memory; a periodic tile store cannot be edited"
            )
    spec = EditSpec(**kw)
    bad = [f for f in spec.image_frames if not 0 <= f < spec.frames]
    if bad:
        raise TerrabenchError(f"{source}: image_frames {bad} outside [0, {spec.frames - 1}]")
    return spec


def way_points(p: EditProgramme, hf: HeightField) -> np.ndarray:
    """float64 (n, 2) way-points in world metres (the terrain's frame)."""
    pts = np.array(p.path, dtype=np.float64)
    if p.units == "fraction":
        pts = np.asarray(hf.origin[:2]) + pts * np.asarray(hf.extent)
    return pts


def check_programme(spec: EditSpec, hf: HeightField) -> None:
    """Refuse, by name, a programme that does not fit the terrain: a radius beyond its larger extent, a way-point
    off it, or a brush check_brush refuses."""
    ox, oy, _ = hf.origin
    w, d = hf.extent
    for r in spec.edit.radii:
        if r > max(w, d):
            raise TerrabenchError(
                f"spec {spec.name!r} [edit]: radius {r:g} m is larger than terrain {hf.name!r} "
                f"({w:g} x {d:g} m); radii must lie in (0, {max(w, d):g}] m"
            )
    for k, (x, y) in enumerate(way_points(spec.edit, hf), start=1):
        if not (ox <= x <= ox + w and oy <= y <= oy + d):
            raise TerrabenchError(
                f"spec {spec.name!r} [edit]: path way-point {k} ({x:g}, {y:g}) m lies off terrain "
                f"{hf.name!r}, which spans x {ox:g} .. {ox + w:g} and y {oy:g} .. {oy + d:g} m"
            )
    for r in spec.edit.radii:
        for frame in frame_brushes(spec, hf, r):
            for b in frame:
                check_brush(b, hf)
    spec_deformation(spec, hf)


def spec_deformation(spec: EditSpec, hf: HeightField):
    """The programme's deformation in world metres (hf's frame), checked against the terrain; None if it names
    none."""
    p = spec.edit
    return None if p.deformation is None else deformation(p.deformation, p.units, hf, spec.name)


def frame_brushes(spec: EditSpec, hf: HeightField, radius: float) -> list[list[Brush]]:
    """The brushes applied before each frame's draw (world metres, hf's frame): ``edits_per_frame`` a frame, spaced
    evenly along the path by length, the same for every method."""
    p = spec.edit
    pts = way_points(p, hf)
    n = spec.frames * p.edits_per_frame
    if n == 0:
        return [[] for _ in range(spec.frames)]
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    s = np.linspace(0.0, along[-1], n)
    xs, ys = np.interp(s, along, pts[:, 0]), np.interp(s, along, pts[:, 1])
    cls = BRUSHES[p.brush]
    extra = {"height": p.height} if cls is Flatten else {}
    brushes = [cls(centre=(float(x), float(y)), radius=radius, strength=p.strength, **extra) for x, y in zip(xs, ys)]
    return [brushes[k * p.edits_per_frame : (k + 1) * p.edits_per_frame] for k in range(spec.frames)]
