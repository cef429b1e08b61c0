"""Camera flights: keyframes (eye + target) interpolated smoothly, presets over any terrain, JSON/CSV files.

Interpolation is a centripetal-free uniform Catmull-Rom spline through the keyframes (end keyframes
repeated), applied to eye and target separately; frame k of n sits at parameter k/(n-1) along the
keyframes. Presets keep the eye above the ground by a margin that grows with the local relief (from the
height samples around every eye: hybrid.camera.clearance), and `grazing` stays low but high enough that the
ground ahead rises at most GRAZING_RISE_DEG above its level view: sky above, terrain below.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hybrid.atomic import atomic_path, write_json
from hybrid.camera.clearance import clear_heights, horizon_heights
from hybrid.camera.view import View
from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import HeightField

PRESETS = ("orbit", "flyover", "grazing", "lookdown", "dolly", "transect")
GRAZING_RISE_DEG = 10.0  # the ground ahead of a grazing eye rises at most this far above its level view
GRAZING_RADIUS_CELLS = 4  # the grazing eye clears the samples within this many cells by a tenth of their relief


@dataclass
class Flight:
    """A camera path: keyframe eyes and targets (K x 3, world metres), frame count and camera settings."""

    name: str
    eyes: np.ndarray
    targets: np.ndarray
    frames: int = 60
    fov_y: float = 60.0
    width: int = 640
    height: int = 360
    near: float = 1.0
    far: float = 1.0e6

    def __post_init__(self):
        self.eyes = np.asarray(self.eyes, dtype=np.float64).reshape(-1, 3)
        self.targets = np.asarray(self.targets, dtype=np.float64).reshape(-1, 3)
        if len(self.eyes) < 1 or len(self.eyes) != len(self.targets):
            raise TerrabenchError(
                f"flight {self.name!r}: needs matching eye and target keyframes, got "
                f"{len(self.eyes)} and {len(self.targets)}"
            )
        if not (np.all(np.isfinite(self.eyes)) and np.all(np.isfinite(self.targets))):
            raise TerrabenchError(f"flight {self.name!r}: keyframes must be finite numbers")
        if isinstance(self.frames, bool) or int(self.frames) != self.frames or not (1 <= int(self.frames) <= 100000):
            raise TerrabenchError(
                f"flight {self.name!r}: frames must be an integer in [1, 100000], got {self.frames!r}"
            )
        self.frames = int(self.frames)
        self.view(0)  # validates camera settings

    def _spline(self, pts: np.ndarray, s: float) -> np.ndarray:
        k = len(pts)
        if k == 1:
            return pts[0]
        u = s * (k - 1)
        i = min(int(np.floor(u)), k - 2)
        t = u - i
        p0, p1, p2, p3 = pts[max(i - 1, 0)], pts[i], pts[i + 1], pts[min(i + 2, k - 1)]
        t2, t3 = t * t, t * t * t
        return 0.5 * (
            (2 * p1) + (-p0 + p2) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t2 + (-p0 + 3 * p1 - 3 * p2 + p3) * t3
        )

    def view(self, k: int, width: int | None = None, height: int | None = None) -> View:
        """The view of frame k (0-based), optionally at another viewport size."""
        if isinstance(k, bool) or int(k) != k or not (0 <= int(k) < self.frames):
            raise TerrabenchError(
                f"frame must be an integer in [0, {self.frames - 1}] for flight {self.name!r}, got {k!r}"
            )
        s = 0.0 if self.frames == 1 else int(k) / (self.frames - 1)
        return View(
            self._spline(self.eyes, s),
            self._spline(self.targets, s),
            self.fov_y,
            width or self.width,
            height or self.height,
            self.near,
            self.far,
        )

    def views(self, width: int | None = None, height: int | None = None) -> list[View]:
        """All frames' views."""
        return [self.view(k, width, height) for k in range(self.frames)]

    # --- files -------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain-data form (JSON-ready)."""
        return {
            "name": self.name,
            "frames": self.frames,
            "fov_y": self.fov_y,
            "width": self.width,
            "height": self.height,
            "near": self.near,
            "far": self.far,
            "keyframes": [{"eye": e.tolist(), "target": t.tolist()} for e, t in zip(self.eyes, self.targets)],
        }

    def save(self, path) -> None:
        """Write the flight as JSON (.json) or CSV (.csv: one keyframe a row; settings in a '#' header)."""
        path = Path(path)
        if path.suffix.lower() == ".json":
            write_json(path, self.to_dict())
        elif path.suffix.lower() == ".csv":
            d = self.to_dict()
            with atomic_path(path) as tmp, tmp.open("w", newline="") as f:
                f.write("# " + json.dumps({k: v for k, v in d.items() if k != "keyframes"}) + "\n")
                w = csv.writer(f)
                w.writerow(["eye_x", "eye_y", "eye_z", "target_x", "target_y", "target_z"])
                for e, t in zip(self.eyes, self.targets):
                    w.writerow([*map(repr, e.tolist()), *map(repr, t.tolist())])
        else:
            raise TerrabenchError(f"{path}: flight files end in .json or .csv")

    @classmethod
    def load(cls, path) -> Flight:
        """Read a flight written by save (JSON or CSV)."""
        path = Path(path)
        if not path.is_file():
            raise TerrabenchError(f"{path}: no such flight file")
        try:
            if path.suffix.lower() == ".json":
                d = json.loads(path.read_text())
                kf = d.pop("keyframes")
                eyes = [k["eye"] for k in kf]
                targets = [k["target"] for k in kf]
            elif path.suffix.lower() == ".csv":
                lines = path.read_text().splitlines()
                d = json.loads(lines[0][1:]) if lines and lines[0].startswith("#") else {}
                rows = list(csv.DictReader(lines[1:] if d else lines))
                eyes = [[float(r[f"eye_{a}"]) for a in "xyz"] for r in rows]
                targets = [[float(r[f"target_{a}"]) for a in "xyz"] for r in rows]
            else:
                raise TerrabenchError(f"{path}: flight files end in .json or .csv")
            allowed = {"name", "frames", "fov_y", "width", "height", "near", "far"}
            extra = set(d) - allowed
            if extra:
                raise TerrabenchError(f"{path}: unknown flight settings {sorted(extra)}")
            d.setdefault("name", path.stem)
            return cls(eyes=np.asarray(eyes, dtype=np.float64), targets=np.asarray(targets, dtype=np.float64), **d)
        except (KeyError, ValueError, TypeError, json.JSONDecodeError) as exc:
            if isinstance(exc, TerrabenchError):
                raise
            raise TerrabenchError(f"{path}: malformed flight file ({type(exc).__name__}: {exc})") from None


def _stencil_heights(hf: HeightField, x: np.ndarray, y: np.ndarray, radius: float) -> np.ndarray:
    """Ground (world z) at each (x, y) and at 16 points around it within ``radius`` metres: shape (17, len(x))."""
    out = [hf.ground_height(x, y)]
    for ang in np.linspace(0, 2 * np.pi, 8, endpoint=False):
        for r in (0.5 * radius, radius):
            out.append(hf.ground_height(x + r * np.cos(ang), y + r * np.sin(ang)))
    return np.array(out)


DOLLY_PITCH_DEG = 8.0


DOLLY_FLOW_PX = 0.6  # the dolly's image motion a frame at the bottom of its view over flat ground (px)


def _dolly_line(hf: HeightField, k: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Eyes and targets of a dolly advancing ``step`` metres a frame (see ``_dolly``)."""
    w, d = hf.extent
    ox, oy, _ = hf.origin
    size = max(w, d)
    heading = np.array([w, d]) / np.hypot(w, d)
    x = ox + 0.3 * w + k * step * heading[0]
    y = oy + 0.3 * d + k * step * heading[1]
    ground = _stencil_heights(hf, x, y, 0.02 * size)
    high, low = ground.max(), ground.min()
    z = np.full(len(k), high + max(30.0, 0.2 * (high - low)))
    eyes = np.stack([x, y, z], 1)
    ahead = 0.1 * size
    targets = eyes + [ahead * heading[0], ahead * heading[1], -ahead * np.tan(np.radians(DOLLY_PITCH_DEG))]
    return eyes, targets


TRANSECT_PITCH_DEG = 15.0


def _transect(hf: HeightField, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eyes and targets (world metres) of the transect at path fractions s in [0, 1]: a straight level line from
    20 % to 60 % of the terrain's south-west to north-east diagonal at one height (the highest ground within 3 % of
    the terrain's size of any point of it, plus max(30 m, 1 % of the size, 20 % of that neighbourhood's relief)),
    looking along it TRANSECT_PITCH_DEG below the horizon. Scaled to the extent, so a larger terrain streams
    through as many tiles of its pyramid."""
    w, d = hf.extent
    ox, oy, _ = hf.origin
    size = max(w, d)
    heading = np.array([w, d]) / np.hypot(w, d)
    x, y = ox + w * (0.2 + 0.4 * s), oy + d * (0.2 + 0.4 * s)
    ground = _stencil_heights(hf, x, y, 0.03 * size)
    high, low = ground.max(), ground.min()
    z = np.full(len(s), high + max(30.0, 0.01 * size, 0.2 * (high - low)))
    eyes = np.stack([x, y, z], 1)
    ahead = 0.15 * size
    targets = eyes + [ahead * heading[0], ahead * heading[1], -ahead * np.tan(np.radians(TRANSECT_PITCH_DEG))]
    return eyes, targets


def _dolly(hf: HeightField, k: np.ndarray, fov_y: float, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Eyes and targets (world metres) of the dolly at frame numbers k: a straight level line to the north-east.

    One height for the whole line: the highest ground within 2 % of the terrain's size of any point of it,
    plus max(30 m, 20 % of that neighbourhood's relief); it looks along the line, DOLLY_PITCH_DEG below the
    horizon. The eye advances at most max(2 m, s / 40) a frame (s the finer of spacing_x and spacing_y), and
    less where that would move the ground at the bottom of the view by more than DOLLY_FLOW_PX pixels a frame:
    a ground point seen at angle a below the horizon from height c moves step * sin²(a) / c radians a frame.
    """
    step = max(2.0, min(hf.spacing_x, hf.spacing_y) / 40.0)
    px_per_rad = height / (2.0 * np.tan(np.radians(fov_y) / 2))
    sin2 = np.sin(np.radians(DOLLY_PITCH_DEG + fov_y / 2)) ** 2
    for _ in range(2):  # the line's height depends on its length: settle the step twice
        eyes, _targets = _dolly_line(hf, k, step)
        clearance = float(np.min(eyes[:, 2] - hf.ground_height(eyes[:, 0], eyes[:, 1])))
        step = min(step, DOLLY_FLOW_PX * clearance / (sin2 * px_per_rad))
    return _dolly_line(hf, k, step)


def preset(
    name: str, hf: HeightField, frames: int = 60, width: int = 640, height: int = 360, fov_y: float = 60.0
) -> Flight:
    """A named flight over hf: orbit, flyover (low), grazing (low, level, the horizon in view), lookdown, dolly
    (slow, straight and level, low over the terrain, looking ahead and slightly down) or transect (straight and
    level across the terrain, looking ahead and down: like content every frame, new tiles all along)."""
    w, d = hf.extent
    ox, oy, oz = hf.origin
    lo, hi = hf.height_range
    size = max(w, d)
    cx, cy = ox + w / 2, oy + d / 2
    far = size * 4 + (hi - lo) * 4
    # ground-following presets get one keyframe per frame, so every frame keeps its clearance exactly
    n_key = max(int(frames), 2) if name in ("flyover", "grazing", "dolly") else 8
    s = np.linspace(0.0, 1.0, n_key)
    if name == "orbit":
        ang = np.radians(225.0) + s * np.pi * 2 * 0.75
        r = 0.75 * size
        eyes = np.stack([cx + r * np.cos(ang), cy + r * np.sin(ang), np.full(n_key, oz + hi + 0.35 * size)], 1)
        targets = np.tile([cx, cy, oz + lo], (n_key, 1))
        near = max(0.5, size * 1e-5)
    elif name == "flyover":
        x = ox + w * (0.1 + 0.8 * s)
        y = oy + d * (0.15 + 0.7 * s) + d * 0.08 * np.sin(s * np.pi * 2)
        z = clear_heights(hf, x, y, 0.03 * size, floor=max(30.0, 0.01 * size), relief_frac=0.2)
        eyes = np.stack([x, y, z], 1)
        ahead = np.stack([x + 0.15 * w, y + 0.12 * d], 1)
        tz = hf.ground_height(ahead[:, 0], ahead[:, 1])
        targets = np.stack([ahead[:, 0], ahead[:, 1], np.minimum(tz, z - 0.02 * size)], 1)
        near = 1.0
    elif name == "grazing":
        x = ox + w * (0.2 + 0.3 * s)
        y = oy + d * (0.2 + 0.3 * s)
        heading = np.array([w, 0.8 * d]) / np.hypot(w, 0.8 * d)
        radius = GRAZING_RADIUS_CELLS * max(hf.spacing_x, hf.spacing_y)
        half_width = np.arctan(np.tan(np.radians(fov_y) / 2) * width / height)
        z = np.maximum(
            clear_heights(hf, x, y, radius, floor=2.0, relief_frac=0.1),
            horizon_heights(hf, x, y, heading, half_width, np.radians(GRAZING_RISE_DEG)),
        )
        eyes = np.stack([x, y, z], 1)
        targets = np.stack([x + w, y + d * 0.8, z], 1)
        near = 0.25
    elif name == "lookdown":
        x = cx + 0.2 * w * np.cos(s * np.pi)
        y = cy + 0.2 * d * np.sin(s * np.pi)
        z = np.full(n_key, oz + hi + 0.25 * size)
        eyes = np.stack([x, y, z], 1)
        targets = np.stack([x, y, np.full(n_key, oz + lo)], 1)
        near = max(0.5, size * 1e-5)
    elif name == "dolly":
        eyes, targets = _dolly(hf, s * (n_key - 1), fov_y, height)
        near = 1.0
    elif name == "transect":
        eyes, targets = _transect(hf, s)
        near = 1.0
    else:
        raise TerrabenchError(f"unknown flight {name!r}; choose one of {', '.join(PRESETS)} or give a .json/.csv file")
    return Flight(f"{name}", eyes, targets, frames, fov_y, width, height, near, far)


def get_flight(name_or_path: str, hf: HeightField, frames: int = 60, width: int = 640, height: int = 360) -> Flight:
    """A preset by name, or a flight file (.json/.csv)."""
    if name_or_path in PRESETS:
        return preset(name_or_path, hf, frames, width, height)
    p = Path(name_or_path)
    if p.suffix.lower() in (".json", ".csv"):
        return Flight.load(p)
    raise TerrabenchError(
        f"unknown flight {name_or_path!r}; choose one of {', '.join(PRESETS)} or give a .json/.csv file"
    )
