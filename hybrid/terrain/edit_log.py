"""The edit log: a sequence of brush edits in JSON lines that replays the same edits on any run.

Line 1 is a header naming the terrain the log was made for (its size, spacing, origin and a digest of its heights
on a sparse lattice, cheap at any size); every other line is one edit: the frame it lands in, the brush's name,
centre (world metres, the terrain's frame), radius (m), strength and, for ``flatten``, the target world z (m);
or one deformation driven by time (``hybrid.terrain.deform``): its name, centre, radius, its amplitude (m),
wavelength (m) and speed (m/s) for a ``wave``, its rate (m/s) for an ``uplift``, and its start and end (s on the
editor's clock). A log read for another terrain, or a malformed line, is refused by line number before anything
is applied.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hybrid.atomic import write_text
from hybrid.errors import TerrabenchError
from hybrid.terrain.deform import DEFORMATION_TYPES, Deformation, Wave, check_deformation
from hybrid.terrain.edits import BRUSHES, Brush, Flatten, check_brush
from hybrid.terrain.heightfield import HeightField

FORMAT = 1  # the header's "terrabench_edits" version
DIGEST_LATTICE = 64  # samples a side of the lattice the digest reads
EDIT_KEYS = {"frame", "brush", "centre", "radius", "strength"}
DEFORMATION_KEYS = {
    "wave": {"deformation", "centre", "radius", "amplitude", "wavelength", "speed", "start", "end"},
    "uplift": {"deformation", "centre", "radius", "rate", "start", "end"},
}


@dataclass(frozen=True)
class TerrainId:
    """What identifies the terrain a log was made for: name, samples (rows, cols), spacing (x, y) and origin
    (x, y, z) in metres, and a digest of its heights on a sparse lattice."""

    name: str
    rows: int
    cols: int
    spacing: tuple[float, ...]
    origin: tuple[float, ...]
    digest: str


@dataclass(frozen=True)
class LoggedEdit:
    """One edit of a log: the frame (>= 0) it is applied before, and the brush."""

    frame: int
    brush: Brush


@dataclass(frozen=True)
class LoggedDeformation:
    """One deformation of a log: its start and end (s on the editor's clock), and the deformation."""

    start: float
    end: float
    deformation: Deformation


@dataclass(frozen=True)
class EditLog:
    """A terrain's identity, its edits in order and its deformations."""

    terrain: TerrainId
    edits: tuple[LoggedEdit, ...]
    deformations: tuple[LoggedDeformation, ...] = ()


def terrain_id(hf: HeightField) -> TerrainId:
    """hf's identity (``TerrainId``); the digest reads at most DIGEST_LATTICE² samples, whatever the grid's size."""
    rows = np.unique(np.linspace(0, hf.rows - 1, min(DIGEST_LATTICE, hf.rows)).round().astype(np.int64))
    cols = np.unique(np.linspace(0, hf.cols - 1, min(DIGEST_LATTICE, hf.cols)).round().astype(np.int64))
    lattice = np.ascontiguousarray(np.asarray(hf.heights[np.ix_(rows, cols)], dtype="<f4"))
    digest = hashlib.sha256(lattice.tobytes()).hexdigest()[:32]
    return TerrainId(hf.name, hf.rows, hf.cols, (hf.spacing_x, hf.spacing_y), tuple(hf.origin), digest)


def _header(tid: TerrainId) -> dict:
    return {
        "terrabench_edits": FORMAT,
        "terrain": {
            "name": tid.name,
            "rows": tid.rows,
            "cols": tid.cols,
            "spacing": list(tid.spacing),
            "origin": list(tid.origin),
            "digest": tid.digest,
        },
    }


def edit_record(edit: LoggedEdit) -> dict:
    """One edit as its log line's JSON object."""
    b = edit.brush
    out = {
        "frame": int(edit.frame),
        "brush": b.kind,
        "centre": [float(v) for v in b.centre],
        "radius": float(b.radius),
        "strength": float(b.strength),
    }
    if isinstance(b, Flatten):
        out["height"] = float(b.height)
    return out


def deformation_record(d: LoggedDeformation) -> dict:
    """One deformation as its log line's JSON object."""
    x = d.deformation
    out: dict = {"deformation": x.kind, "centre": [float(v) for v in x.centre], "radius": float(x.radius)}
    if isinstance(x, Wave):
        out.update(amplitude=float(x.amplitude), wavelength=float(x.wavelength), speed=float(x.speed))
    else:
        out["rate"] = float(x.rate)
    return {**out, "start": float(d.start), "end": float(d.end)}


def write_log(path, log: EditLog) -> Path:
    """Write an edit log as JSON lines, atomically (the file lands whole or not at all)."""
    lines = (
        [json.dumps(_header(log.terrain))]
        + [json.dumps(edit_record(e)) for e in log.edits]
        + [json.dumps(deformation_record(d)) for d in log.deformations]
    )
    return write_text(path, "\n".join(lines) + "\n")


def _parse_header(obj, where: str) -> TerrainId:
    if not isinstance(obj, dict) or obj.get("terrabench_edits") != FORMAT or not isinstance(obj.get("terrain"), dict):
        raise TerrabenchError(
            f'{where}: the first line must be the header {{"terrabench_edits": {FORMAT}, '
            '"terrain": {...}}, as terrabench writes it'
        )
    t = obj["terrain"]
    try:
        return TerrainId(
            str(t["name"]),
            int(t["rows"]),
            int(t["cols"]),
            tuple(float(v) for v in t["spacing"]),
            tuple(float(v) for v in t["origin"]),
            str(t["digest"]),
        )
    except (KeyError, TypeError, ValueError):
        raise TerrabenchError(
            f"{where}: the header's terrain needs name, rows, cols, spacing, origin and digest, "
            f"got {json.dumps(t)[:200]}"
        ) from None


def _keys(obj: dict, keys: set, what: str, where: str) -> None:
    """Refuse an object whose keys are not exactly ``keys``, naming the missing and unknown ones."""
    if set(obj) != keys:
        missing, extra = sorted(keys - set(obj)), sorted(set(obj) - keys)
        raise TerrabenchError(
            f"{where}: a {what} has keys {', '.join(sorted(keys))}"
            + (f"; missing {', '.join(missing)}" if missing else "")
            + (f"; unknown {', '.join(extra)}" if extra else "")
        )


def _centre(obj: dict, where: str) -> tuple[float, float]:
    centre = obj["centre"]
    if (
        not isinstance(centre, list)
        or len(centre) != 2
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in centre)
    ):
        raise TerrabenchError(f"{where}: centre must be [x, y] in metres, got {centre!r}")
    return float(centre[0]), float(centre[1])


def _numbers(obj: dict, keys: set, where: str) -> dict:
    for k in sorted(keys):
        if isinstance(obj[k], bool) or not isinstance(obj[k], (int, float)):
            raise TerrabenchError(f"{where}: {k} must be a number, got {obj[k]!r}")
    return {k: float(obj[k]) for k in keys}


def _parse_deformation(obj: dict, where: str) -> LoggedDeformation:
    kind = obj.get("deformation")
    if kind not in DEFORMATION_KEYS:
        raise TerrabenchError(f"{where}: deformation must be one of {', '.join(DEFORMATION_KEYS)}, got {kind!r}")
    keys = DEFORMATION_KEYS[kind]
    _keys(obj, keys, f"{kind} deformation", where)
    args = _numbers(obj, keys - {"deformation", "centre"}, where)
    start, end = args.pop("start"), args.pop("end")
    return LoggedDeformation(start, end, DEFORMATION_TYPES[kind](centre=_centre(obj, where), **args))


def _parse_edit(obj, where: str) -> LoggedEdit | LoggedDeformation:
    if not isinstance(obj, dict):
        raise TerrabenchError(f"{where}: an edit must be a JSON object, got {type(obj).__name__}")
    if "deformation" in obj:
        return _parse_deformation(obj, where)
    kind = obj.get("brush")
    if kind not in BRUSHES:
        raise TerrabenchError(f"{where}: brush must be one of {', '.join(BRUSHES)}, got {kind!r}")
    keys = EDIT_KEYS | ({"height"} if kind == "flatten" else set())
    _keys(obj, keys, f"{kind} edit", where)
    frame = obj["frame"]
    if isinstance(frame, bool) or not isinstance(frame, int) or frame < 0:
        raise TerrabenchError(f"{where}: frame must be an integer >= 0, got {frame!r}")
    args = _numbers(obj, keys - {"frame", "brush", "centre"}, where)
    return LoggedEdit(frame, BRUSHES[kind](centre=_centre(obj, where), **args))


def _json(line: str, where: str):
    try:
        return json.loads(line)
    except json.JSONDecodeError as exc:
        raise TerrabenchError(f"{where}: not JSON ({exc.msg} at column {exc.colno})") from None


def read_log(path) -> EditLog:
    """An edit log read from JSON lines; a missing file, a bad header or a malformed line (named by its number) is
    refused. Blank lines are skipped; frames must not go back."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise TerrabenchError(f"cannot read edit log {path}: {getattr(exc, 'strerror', None) or exc}") from None
    lines = [(n, s) for n, s in enumerate(text.splitlines(), start=1) if s.strip()]
    if not lines:
        raise TerrabenchError(f"edit log {path} is empty: it needs at least its header line")
    tid = _parse_header(_json(lines[0][1], f"{path} line {lines[0][0]}"), f"{path} line {lines[0][0]}")
    edits, deformations, last = [], [], 0
    for n, s in lines[1:]:
        where = f"{path} line {n}"
        e = _parse_edit(_json(s, where), where)
        if isinstance(e, LoggedDeformation):
            deformations.append(e)
            continue
        if e.frame < last:
            raise TerrabenchError(f"{where}: frame {e.frame} comes after frame {last}; frames must not go back")
        last = e.frame
        edits.append(e)
    return EditLog(tid, tuple(edits), tuple(deformations))


def check_log(log: EditLog, hf: HeightField, path="edit log") -> EditLog:
    """The log if it was made for hf (size, spacing, origin and height digest) and every brush fits hf, else a
    TerrabenchError naming the difference or the edit."""
    mine = terrain_id(hf)
    t = log.terrain
    for what, theirs, ours in (
        ("samples (rows, cols)", (t.rows, t.cols), (mine.rows, mine.cols)),
        ("spacing (m)", t.spacing, mine.spacing),
        ("origin (m)", t.origin, mine.origin),
        ("height digest", t.digest, mine.digest),
    ):
        if tuple(np.atleast_1d(theirs)) != tuple(np.atleast_1d(ours)):
            raise TerrabenchError(
                f"{path} was made for terrain {t.name!r} with {what} {theirs}, not this terrain "
                f"{hf.name!r} with {ours}; replay it on the terrain it was made for"
            )
    for k, e in enumerate(log.edits, start=1):
        try:
            check_brush(e.brush, hf)
        except TerrabenchError as exc:
            raise TerrabenchError(f"{path} edit {k}: {exc}") from None
    for k, d in enumerate(log.deformations, start=1):
        try:
            check_deformation(d.deformation, hf, d.start, d.end)
        except TerrabenchError as exc:
            raise TerrabenchError(f"{path} deformation {k}: {exc}") from None
    return log
