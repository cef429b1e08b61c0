"""`terrabench run` of an edit spec (kind = "edit"): every method follows the same edits over the same views.

Each configuration (a method at one brush radius, or on the static terrain) holds its own copy of the terrain, its
renderer, a ``hybrid.editing.TerrainEditor`` (editing only) and its particles on the GPU heights. Before frame k's
draw every configuration applies the programme's edits of frame k (the editor times each step) and steps its
particles once (timed apart); then the frame is drawn ``repeats`` times, configurations in turn with the first
rotating from draw to draw, the particles drawn into each frame after its timed draw (timed apart). One more,
untimed, draw without particles is what accuracy is measured on, against the reference renderer of the same
edited heights (one per radius, following the same edits, and one of the static terrain). Accuracy is computed
after every frame has been timed, so the metrics' threads never run between timed draws.

A run folder holds spec.json, env.json, one edit log a radius (``edits-r<radius>m.jsonl``, replayable with
``terrabench render --edit``), frames.jsonl (the journal), frames.parquet, tiles.parquet, errors.jsonl and images/.
The edits of a frame depend on every frame before it, so a resumed run replays every frame of the configurations
it still lacks frames of and journals only those frames.
"""

from __future__ import annotations

import time
import traceback
from pathlib import Path
from typing import Any

import numpy as np

from hybrid.atomic import remove_stale_temps, write_json
from hybrid.errors import TerrabenchError

from .config_task import ConfigResult, ImageOut
from .edit_spec import EditSpec, check_programme, frame_brushes, spec_deformation
from .journal import Journal, pending, record
from .metrics import frame_accuracy
from .popping import temporal_errors
from .progress import Progress
from .run_config import EditConfig
from .runlock import RunLock

SETTLE_S = 0.3  # seconds of idle before the timed frames


def _copy(hf):
    """A height field with its own heights (edits change them in place)."""
    from hybrid.terrain.heightfield import HeightField

    return HeightField(
        hf.heights.copy(),
        hf.spacing,
        hf.origin,
        hf.name,
        hf.texture,
        hf.nodata_filled,
        hf.source,
        list(hf.notes),
        hf.source_step,
    )


def _rotated(items: list, shift: int) -> list:
    """items with the first ``shift`` (mod len) moved to the end."""
    if not items:
        return items
    s = shift % len(items)
    return items[s:] + items[:s]


class _Member:
    """One configuration being run: its terrain copy, renderer, editor, GPU heights, particles and what it timed."""

    def __init__(self, c: EditConfig, todo: list[int], brushes: list[list], deform=None):
        self.c, self.todo, self.brushes = c, todo, brushes
        self.deform = deform if c.editing else None  # (deformation, its programme) or None
        self.renderer: Any = None  # GPU state, made by open()
        self.editor: Any = None
        self.heights: Any = None
        self.particles: Any = None
        self.updates: dict[int, dict] = {}
        self.steps: dict = {}
        self.draws: list = []
        self.timed: dict[int, dict] = {}
        self.plain: dict = {}
        self.out = ConfigResult(c)
        self.gpu_bytes: dict = {}

    def open(self, ctx, spec: EditSpec, hf, view) -> None:
        """Make its GPU state on a copy of hf and draw one untimed frame (compiles, first uploads)."""
        from hybrid.editing import TerrainEditor
        from hybrid.gl.brush import GpuHeights
        from hybrid.gl.particles import ParticleParams, ParticleSystem
        from hybrid.renderer import make_renderer
        from hybrid.strategies import mixed_policies

        hf = _copy(hf)
        mixed = {"adapt": spec.adapt, "reuse_choice": 1} if self.c.policy in mixed_policies() else {}  # every frame
        self.renderer = make_renderer(ctx, hf, self.c.policy, tile_size=spec.tile_size, **mixed)
        if self.c.editing:
            self.editor = TerrainEditor(ctx, hf, self.renderer)
            self.heights = self.editor.gpu
            if self.deform is not None:
                d, p = self.deform
                self.editor.deform(d, p.start, p.end)
        else:
            self.heights = GpuHeights(ctx, hf)
        self.particles = ParticleSystem(ctx, self.heights, ParticleParams(count=spec.edit.particles, seed=spec.seed))
        self.renderer.render(view, spec.tau, overlay=self.particles.draw)
        self.gpu_bytes = {"edit_gpu_bytes": self.heights.nbytes, "particles_bytes": self.particles.nbytes}

    def edit(self, k: int) -> None:
        """Apply frame k's edits and set its deformation's time (its editor times each step) and step the particles
        once (timed)."""
        cols: dict = {"edits": len(self.brushes[k]), "update_ms": 0.0, "edit_tiles": 0, "edit_refreshed": 0}
        reports = [self.editor.apply(b) for b in self.brushes[k]]
        if self.deform is not None:
            t0 = time.perf_counter()
            self.editor.step(self.deform[1].time(k))
            self.editor.ctx.finish()
            cols["update_deform_ms"] = (time.perf_counter() - t0) * 1e3
            cols["update_ms"] += cols["update_deform_ms"]
            reports.append(self.editor.sync())
        for rep in reports:
            cols["edit_tiles"] += rep.tiles
            cols["edit_refreshed"] += sum(rep.refreshed.values())
            for step, ms in rep.ms.items():
                cols[f"update_{step}_ms"] = cols.get(f"update_{step}_ms", 0.0) + ms
                cols["update_ms"] += ms
        self.updates[k] = cols
        self.steps[k] = self.particles.timed_step()

    def draw_plain(self, k: int, view, tau: float) -> None:
        """Frame k drawn once more, untimed and without particles: what accuracy is measured on."""
        self.plain[k] = self.renderer.render(view, tau)

    def overlay(self, target, view) -> None:
        """Draw the particles into a frame's target, timed apart."""
        self.draws.append(self.particles.timed_draw(target, view))

    def attempt(self, fn, fail_fast: bool) -> None:
        """Run fn(); a failure ends this configuration (its error kept, GPU state released), not the run."""
        if self.out.error is not None:
            return
        try:
            fn()
        except Exception as exc:  # a failed configuration is journalled; the others go on
            if fail_fast:
                raise
            msg = str(exc) if isinstance(exc, TerrabenchError) else f"{type(exc).__name__}: {exc}"
            self.out.error = {**self.c.row(), "error": msg, "trace": traceback.format_exc(limit=4)}
            self.release()

    def release(self) -> None:
        """Free its GPU state."""
        for o in (self.particles, self.editor, self.renderer):
            if o is not None:
                o.release()
        if self.editor is None and self.heights is not None:
            self.heights.release()
        self.renderer = self.editor = self.heights = self.particles = None


class _Reference:
    """The reference renderer of one edit variant (a radius, or the static terrain), following the same edits."""

    def __init__(self, ctx, hf, brushes: list[list], deform=None):
        from hybrid.editing import TerrainEditor
        from hybrid.reference import ReferenceRenderer

        self.hf = _copy(hf)
        self.brushes, self.deform = brushes, deform
        self.ref = ReferenceRenderer(ctx, self.hf)
        editor = TerrainEditor(ctx, self.hf, None, self.ref) if any(brushes) or deform else None
        if editor is not None and deform is not None:
            editor.deform(deform[0], deform[1].start, deform[1].end)
        self.editor: Any = editor

    def frame(self, k: int, view, supersample: int):
        """Frame k's reference image after frame k's edits and deformation time (untimed)."""
        for b in self.brushes[k]:
            self.editor.apply(b)
        if self.deform is not None:
            self.editor.step(self.deform[1].time(k))
            self.editor.sync()
        return self.ref.render(view, supersample=supersample)

    def release(self) -> None:
        """Free its GPU state."""
        if self.editor is not None:
            self.editor.release()
        self.ref.release()


def prepare(spec: EditSpec) -> tuple:
    """(terrain, views, brushes per radius, (deformation, its programme) or None) of a spec, every value checked
    against the terrain: a TerrabenchError naming the first that does not fit, before any folder is made."""
    from hybrid.camera.clearance import check_eye_above
    from hybrid.camera.flight import get_flight
    from hybrid.camera.view import parse_size

    from .spec_datasets import check_dataset_paths

    check_dataset_paths([spec.dataset], f"spec {spec.name!r}")
    hf = spec.terrain()
    if not isinstance(hf.heights, np.ndarray):
        raise TerrabenchError(
            f"spec {spec.name!r}: dataset {spec.label!r} is a tile store; an edit spec edits terrain held in memory"
        )
    check_programme(spec, hf)
    w, h = parse_size(spec.sizes[0])
    views = get_flight(spec.flight, hf, frames=spec.frames, width=w, height=h).views()
    for k, v in enumerate(views):
        check_eye_above(hf, v, f"flight {spec.flight} frame {k}")
    programme = {r: frame_brushes(spec, hf, r) for r in spec.edit.radii}
    programme[0.0] = [[] for _ in range(spec.frames)]
    d = spec_deformation(spec, hf)
    return hf, views, programme, (None if d is None else (d, spec.edit.deformation))


def _open_folder(spec: EditSpec, runs_dir: Path) -> Path:
    folder = Path(runs_dir) / spec.name
    try:
        (folder / "images").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TerrabenchError(f"cannot create run folder {folder}: {exc.strerror or exc}") from None
    return folder


def run_edit_spec(spec: EditSpec, runs_dir, ctx=None, progress: bool = True, fail_fast: bool = False) -> Path:
    """Run (or resume) an edit spec into runs_dir/<name>; returns the run folder."""
    from hybrid.gl.context import shared_context
    from hybrid.terrain.edit_log import EditLog, LoggedDeformation, LoggedEdit, terrain_id, write_log

    from .environment import environment
    from .folders import read_json

    hf, views, programme, deform = prepare(spec)
    folder = _open_folder(spec, runs_dir)
    with RunLock(folder):
        for where in (folder, folder / "images"):
            remove_stale_temps(where)
        old = folder / "spec.json"
        if old.exists() and not spec.same_as(read_json(old, "run spec")):
            raise TerrabenchError(f"{folder} holds a run of a different spec; choose another name or folder")
        write_json(old, spec.to_dict())
        ctx = ctx or shared_context()
        write_json(folder / "env.json", environment(ctx))
        tid = terrain_id(hf)
        # replayed (render --edit) at the deformation's end: the terrain of a frame at or after it
        deforms = () if deform is None else (LoggedDeformation(deform[1].start, deform[1].end, deform[0]),)
        for r in spec.edit.radii:
            edits = tuple(LoggedEdit(k, b) for k, frame in enumerate(programme[r]) for b in frame)
            write_log(folder / f"edits-r{r:g}m.jsonl", EditLog(tid, edits, deforms))
        _run(spec, folder, ctx, (hf, views, programme, deform), progress, fail_fast)
    return folder


def _run(spec: EditSpec, folder: Path, ctx, prepared: tuple, progress: bool, fail_fast: bool) -> None:
    """Time every frame of the configurations the journal lacks frames of, then measure and journal them."""
    from hybrid.gl.context import gl_info

    hf, views, programme, deform = prepared
    journal = Journal(folder)
    todo = pending(spec, journal)
    total = len(spec.configs()) * spec.frames
    bar = Progress(total, total - sum(len(t) for _, t in todo), progress)
    members = [_Member(c, t, programme[c.edit_radius], deform) for c, t in todo]
    radii = sorted({m.c.edit_radius for m in members})
    refs = {r: _Reference(ctx, hf, programme[r], deform if r > 0 else None) for r in radii}
    try:
        for m in members:
            m.attempt(lambda m=m: m.open(ctx, spec, hf, views[0]), fail_fast)
        time.sleep(SETTLE_S)  # threads of earlier work (compiles, uploads) go idle before timing
        shots: dict = {}
        for k in range(spec.frames if members else 0):
            _time_frame(spec, members, k, views[k], fail_fast)
            shots[k] = {r: ref.frame(k, views[k], spec.supersample) for r, ref in refs.items()}
            for m in members:
                if k in m.todo and m.out.error is None:
                    bar.step(f"{m.c.config} frame {k}")
        extra = {"device": gl_info(ctx).renderer, "worker": "local"}
        for m in members:
            m.attempt(lambda m=m: _measure(spec, m, shots, extra), fail_fast)
            record(folder, journal, m.out)
        record(folder, journal, _reference_images(spec, shots))
    finally:
        for m in members:
            m.release()
        for ref in refs.values():
            ref.release()
    bar.close()
    journal.write_tables()


def _time_frame(spec: EditSpec, members: list[_Member], k: int, view, fail_fast: bool) -> None:
    """Frame k of every live configuration: its edits and particle step, ``repeats`` timed draws in rotating turns
    (particles drawn into each), then one untimed draw without particles for accuracy."""
    live = [m for m in members if m.out.error is None]
    for m in _rotated(live, k):
        m.attempt(lambda m=m: m.edit(k), fail_fast)
        m.draws = []
    results: dict = {id(m): [] for m in live}
    for rep in range(spec.repeats):
        for m in _rotated([m for m in live if m.out.error is None], k * spec.repeats + rep):
            m.attempt(
                lambda m=m: results[id(m)].append(m.renderer.render(view, spec.tau, overlay=m.overlay)), fail_fast
            )
    for m in live:
        if m.out.error is not None:
            continue
        m.attempt(lambda m=m: m.draw_plain(k, view, spec.tau), fail_fast)
        shown = results[id(m)][-1]
        m.timed[k] = {
            "walls": [x.stats.wall_ms for x in results[id(m)]],
            "stats": shown.stats,
            "cpu": [x.stats.cpu_ms for x in results[id(m)] if x.stats.cpu_ms is not None],
            "gpu": [x.stats.gpu_ms for x in results[id(m)] if x.stats.gpu_ms is not None],
            "draws": list(m.draws),
            "image": shown if k in spec.image_frames else None,
        }


def _median(values) -> float:
    values = [v for v in values if v is not None]
    return float(np.median(values)) if values else float("nan")


def _measure(spec: EditSpec, m: _Member, shots: dict, extra: dict) -> None:
    """The rows of m's frames to journal: timing, update steps, particles and accuracy against the reference."""
    for k in m.todo:
        t = m.timed[k]
        step, draws = m.steps[k], t["draws"]
        gpu = [step.gpu_ms, _median(d.gpu_ms for d in draws)] if step.gpu_ms is not None else None
        row = {
            **m.c.row(),
            "frame": k,
            **t["stats"].row(),
            **extra,
            "wall_ms": _median(t["walls"]),
            "cpu_ms": _median(t["cpu"]),
            "gpu_ms": _median(t["gpu"]),
            "wall_ms_min": float(np.min(t["walls"])),
            "wall_ms_max": float(np.max(t["walls"])),
            "wall_ms_repeats": [float(w) for w in t["walls"]],
            **m.updates[k],
            "particles_step_ms": step.wall_ms,
            "particles_draw_ms": _median(d.wall_ms for d in draws),
            "particles_gpu_ms": float(sum(gpu)) if gpu else float("nan"),
            **m.gpu_bytes,
        }
        row["particles_ms"] = row["particles_step_ms"] + row["particles_draw_ms"]
        row.update(frame_accuracy(m.plain[k], shots[k][m.c.edit_radius], flip=spec.flip))
        row.update(_temporal(m, shots, k))
        tiles = [{"config": m.c.config, "frame": k, "policy": m.c.policy, **x} for x in t["stats"].tile_rows]
        m.out.frames.append((row, tiles))
        if t["image"] is not None:
            m.out.images.append(ImageOut(f"{m.c.config}-f{k}", t["image"].colour, t["image"].distance))


def _temporal(m: _Member, shots: dict, k: int) -> dict:
    """Frame k's colour change from frame k-1 against the reference's of the same edited heights
    (``temporal_errors``: change_ratio 1 is as stable as the reference); NaN for a first frame."""
    r = m.c.edit_radius
    if k - 1 not in m.plain or k - 1 not in shots:
        return {"change_ratio": float("nan"), "error_flicker": float("nan")}
    return temporal_errors(m.plain[k - 1], m.plain[k], shots[k - 1][r], shots[k][r])


def _variant(radius: float) -> str:
    return f"r{radius:g}m" if radius > 0 else "static"


def _reference_images(spec: EditSpec, shots: dict) -> ConfigResult:
    """The references of the image frames, one a variant, to save beside the configurations' images."""
    out = ConfigResult(None)
    for k in spec.image_frames:
        for r, res in shots.get(k, {}).items():
            out.images.append(ImageOut(f"ref-{_variant(r)}-f{k}", res.colour, res.distance))
    return out
