"""A group of a spec's configurations, run where a GL context lives: draw and time their frames, then measure them.

A group is the unit of work of a run, the same whether the run is serial (``experiments.runner``) or spread over
a Dask cluster (``experiments.cluster``): it takes the spec, the configurations and the frames still to do,
and returns plain results (frame rows with their tile rows, images to save, or the error) for the caller to
journal. Datasets are loaded where the task runs, from the spec's paths or names, and kept per process.

Timing is kept apart from measuring: a group's frames are all drawn and timed first (results kept in
memory), and only then compared with the references, so the metrics' own threads (FLIP) and the reference
renders never run between timed draws. The configurations of a group (the same paired views and tau, every
policy) are timed interleaved, frame by frame and repeat by repeat, so that a drift of the machine over the
run falls on all of them alike (``run_group``). Each configuration first draws one untimed warm-up frame
(shader compiles, first uploads: one-off costs that are not a frame's); every frame is drawn ``repeats``
times, all kept in ``wall_ms_repeats`` and their median in ``wall_ms``; ``cpu_ms`` is the median of their CPU
shares (planning plus issuing the draw: ``FrameStats.issue_ms``) and ``gpu_ms`` of their GPU times (the
timer query; NaN where the GL has none, as on llvmpipe). Maps for the report's images come from one more,
untimed, draw. A spec with ``accuracy = false`` draws no reference: its rows carry timing only, and no images. A configuration resumed part-way first replays its earlier frames untimed, so
that its GPU tile cache is in the state an uninterrupted run would have.
"""

from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hybrid.camera.view import parse_size
from hybrid.errors import TerrabenchError
from hybrid.reference import ReferenceRenderer
from hybrid.strategies import mixed_policies

from .metrics import frame_accuracy
from .popping import popping, static_pop_pixels, temporal_errors
from .run_config import Config, RunConfig
from .spec import Spec

if TYPE_CHECKING:
    from hybrid.renderer import Renderer

SETTLE_S = 0.3  # seconds of idle before a configuration's timed frames


@dataclass
class ImageOut:
    """An image to save under the run's images/ folder: colour, and with ``full`` its depth and maps."""

    stem: str
    colour: np.ndarray
    distance: np.ndarray | None = None
    maps: dict = field(default_factory=dict)


@dataclass
class ConfigResult:
    """What a configuration task hands back: per frame (row, tile rows), images, and the error if it failed."""

    config: RunConfig | None
    frames: list = field(default_factory=list)
    images: list = field(default_factory=list)
    error: dict | None = None
    unreached: int = 0


def group_id(c: Config) -> str:
    """The stem shared by a configuration's paired frames: dataset, seed, flight and size."""
    return f"{Path(c.dataset).stem}-s{c.seed}-{Path(c.flight).stem}-{c.size}"


class TaskState:
    """What one process keeps between configurations: its GL context, loaded terrains and the references of
    the last group of paired frames (one group at a time, to bound memory)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._terrain: dict = {}
        self._group = None
        self._views = None
        self._refs: dict = {}
        self._reference: ReferenceRenderer | None = None  # the group's, with spec.accuracy
        self.cost_model = None  # the device's calibrated model, when the client sends one
        self.learned = None  # the adapted model of the hybrid that learned most, once it settled

    def views(self, spec: Spec, cfg: Config):
        """The group's terrain and views (checked: every eye above the ground); loads the terrain once."""
        from hybrid.camera.clearance import check_eye_above
        from hybrid.camera.flight import get_flight

        key = (spec.name, group_id(cfg))
        if self._group != key:
            self.release_group()
            tkey = (cfg.dataset, cfg.seed, spec.dataset_size)
            if tkey not in self._terrain:
                self._terrain = {tkey: spec.terrain(cfg.dataset, cfg.seed)}
            hf = self._terrain[tkey]
            w, h = parse_size(cfg.size)
            views = get_flight(cfg.flight, hf, frames=spec.frames, width=w, height=h).views()
            for k, v in enumerate(views):
                check_eye_above(hf, v, f"flight {cfg.flight} frame {k}")
            self._group, self._views = key, (hf, views)
            self._reference = ReferenceRenderer(self.ctx, hf) if spec.accuracy else None
        return self._views

    def reference(self, spec: Spec, c: Config, k: int, images: list):
        """The reference render of frame k of the configuration's group (cached for the group)."""
        if k not in self._refs:
            _, views = self.views(spec, c)
            assert self._reference is not None  # views made it: references are asked for with spec.accuracy
            self._refs[k] = self._reference.render(views[k], supersample=spec.supersample)
            if k in spec.image_frames or spec.video:
                images.append(_image(f"ref-{group_id(c)}-f{k}", self._refs[k], k in spec.image_frames))
        return self._refs[k]

    def release_group(self) -> None:
        """Drop the current group's references and its reference renderer."""
        if self._reference is not None:
            self._reference.release()
        self._group, self._views, self._refs, self._reference = None, None, {}, None


def _image(stem: str, result, full: bool) -> ImageOut:
    return ImageOut(
        stem, result.colour, result.distance if full else None, dict(getattr(result, "maps", {})) if full else {}
    )


def group_key(c: Config) -> tuple:
    """Configurations timed together, frame by frame: the same paired views and the same tau."""
    return (group_id(c), c.tau)


def groups(items: list[tuple[Config, list[int]]]) -> list[list[tuple[Config, list[int]]]]:
    """(configuration, frames to do) pairs gathered by group_key, in the order they first appear."""
    out: dict = {}
    for c, todo in items:
        out.setdefault(group_key(c), []).append((c, todo))
    return list(out.values())


class _ConfigRun:
    """One configuration inside a group: its renderer (GPU state), its timed draws and its result."""

    def __init__(self, cfg: Config, todo: list[int]):
        self.cfg, self.todo = cfg, todo
        self.renderer: Renderer | ReferenceRenderer | None = None  # made by _open, None once released
        self.timed: dict = {}
        self.out = ConfigResult(cfg)

    def attempt(self, fn, fail_fast: bool) -> None:
        """Run fn(); a failure ends this configuration (its error kept, its renderer released), not the group."""
        if self.out.error is not None:
            return
        try:
            fn()
        except Exception as exc:  # a failed configuration is returned; the group goes on with the others
            if fail_fast:
                raise
            self.fail(exc)

    def fail(self, exc: Exception) -> None:
        """Keep exc as this configuration's error and release its renderer."""
        msg = str(exc) if isinstance(exc, TerrabenchError) else f"{type(exc).__name__}: {exc}"
        self.out.error = {**self.cfg.row(), "error": msg, "trace": traceback.format_exc(limit=4)}
        self.out.frames = []
        self.out.images = [i for i in self.out.images if i.stem.startswith("ref-")]  # the group's references
        self.out.unreached = len([k for k in self.todo if k not in self.timed])
        self.release()

    def release(self) -> None:
        """Release the renderer's GPU resources."""
        if self.renderer is not None:
            self.renderer.release()
            self.renderer = None


def run_group(
    spec: Spec,
    items: list[tuple[Config, list[int]]],
    state: TaskState,
    step=None,
    fail_fast: bool = False,
    extra: dict | None = None,
) -> list[ConfigResult]:
    """Draw, time and measure the frames to do of configurations that share their views (one group_key).

    The configurations are timed interleaved: each repeat of a frame is drawn by every configuration in
    turn, the turn's first configuration rotating from draw to draw, so that a drift of the machine over the
    run (clocks, heat, other processes) falls on every configuration alike instead of on whichever ran
    last. ``step(label)`` is called per configuration and timed frame; ``extra`` columns (device, worker) are
    added to every row. A failure is returned in that configuration's result, not raised (unless
    ``fail_fast``), with the frames it never reached counted."""
    runs = [_ConfigRun(c, todo) for c, todo in items]
    try:
        try:
            hf, views = state.views(spec, items[0][0])
        except Exception as exc:
            if fail_fast:
                raise
            for r in runs:
                r.fail(exc)
            return [r.out for r in runs]
        for r in runs:
            r.attempt(lambda r=r: _open(spec, r, state, hf, views), fail_fast)
        time.sleep(SETTLE_S)  # threads of earlier work (compiles, uploads) go idle before timing
        for k in sorted({k for r in runs for k in r.todo}):
            _time_frame(spec, [r for r in runs if k in r.todo], k, views, fail_fast, step)
        for r in runs:
            r.attempt(lambda r=r: _measure(spec, r, state, views, extra), fail_fast)
    finally:
        for r in runs:
            _keep_learned(r, state)
            r.release()
    if extra:
        for r in runs:
            if r.out.error is not None:
                r.out.error.update(extra)
    return [r.out for r in runs]


def _keep_learned(r: _ConfigRun, state: TaskState) -> None:
    """Keep r's adapted cost model in ``state.learned`` when its predictions hold and it learned more frames than
    the one kept (started from the device's model: a fallback's start is a demonstration, not this device's)."""
    online = getattr(r.renderer, "online", None)
    if online is None or not online.settled or r.cfg.start_model != "device":
        return
    if state.learned is None or online.model.adapted_frames > state.learned.adapted_frames:
        state.learned = online.model


def _open(spec: Spec, r: _ConfigRun, state: TaskState, hf, views) -> None:
    """Make r's renderer, replay the frames before its first one to do (a resumed configuration: its cache as
    an uninterrupted run's) and draw that frame once untimed (compiles, first uploads: one-off costs)."""
    from hybrid.cost.model import fallback_cost_model
    from hybrid.renderer import make_renderer

    c, model = r.cfg, state.cost_model
    if c.start_model == "fallback":
        model = fallback_cost_model()
    mixed = (
        {"adapt": spec.adapt, "reuse_choice": spec.reuse_choice, **({"cost_model": model} if model is not None else {})}
        if c.policy in mixed_policies()
        else {}
    )
    r.renderer = make_renderer(
        state.ctx,
        hf,
        c.policy,
        tile_size=spec.tile_size,
        reconstruction=c.reconstruction,
        budget_bytes=spec.gpu_budget_mib << 20,
        full_res=c.full_res,
        upload_budget_ms=spec.upload_budget_ms,
        **mixed,
    )
    for k in range(r.todo[0]):
        r.renderer.render(views[k], c.tau)
    r.renderer.render(views[r.todo[0]], c.tau)


def _time_frame(spec: Spec, live: list[_ConfigRun], k: int, views, fail_fast: bool, step) -> None:
    """Time frame k: ``spec.repeats`` rounds, each drawn by every live configuration, the first one rotating."""
    draws: dict = {id(r): [] for r in live}
    for rep in range(spec.repeats):
        turn = [r for r in live if r.out.error is None]
        if not turn:
            return
        shift = (k * spec.repeats + rep) % len(turn)
        for r in turn[shift:] + turn[:shift]:
            r.attempt(lambda r=r: draws[id(r)].append(r.renderer.render(views[k], r.cfg.tau)), fail_fast)
    for r in live:
        if r.out.error is not None:
            continue
        results = draws[id(r)]
        mapped: list = []
        if spec.accuracy and k in spec.image_frames and r.cfg.policy in mixed_policies():  # untimed, for its maps
            r.attempt(
                lambda r=r, mapped=mapped: mapped.append(r.renderer.render(views[k], r.cfg.tau, maps=True)), fail_fast
            )
        if r.out.error is not None:
            continue
        cpu = [x.stats.cpu_ms for x in results if x.stats.cpu_ms is not None]
        gpu = [x.stats.gpu_ms for x in results if x.stats.gpu_ms is not None]
        r.timed[k] = ((mapped or results)[-1], [x.stats.wall_ms for x in results], results[-1].stats, cpu, gpu)
        if step:
            step(f"{r.cfg.config} frame {k}")


def _measure(spec: Spec, r: _ConfigRun, state: TaskState, views, extra: dict | None) -> None:
    """Rows of r's timed frames, with their accuracy against the references unless the spec says accuracy =
    false; neighbours a resumed run did not time are drawn now (untimed) for the temporal measures."""
    cfg, out = r.cfg, r.out
    drawn = {k: v[0] for k, v in r.timed.items()}
    for k in r.todo:
        res, walls, timed_stats, cpu, gpu = r.timed[k]  # counters of a timed draw, not the maps draw
        row = {
            **cfg.row(),
            "frame": k,
            **timed_stats.row(),
            **(extra or {}),
            "wall_ms": float(np.median(walls)),
            "cpu_ms": float(np.median(cpu)) if cpu else float("nan"),
            "gpu_ms": float(np.median(gpu)) if gpu else float("nan"),
            "wall_ms_min": float(np.min(walls)),
            "wall_ms_max": float(np.max(walls)),
            "wall_ms_repeats": [float(w) for w in walls],
        }
        if spec.accuracy:
            row.update(_accuracy(spec, r, state, views, k, res, drawn))
        tiles = [{"config": cfg.config, "frame": k, "policy": cfg.policy, **t} for t in timed_stats.tile_rows]
        out.frames.append((row, tiles))
        if spec.accuracy and (k in spec.image_frames or spec.video):
            out.images.append(_image(f"{cfg.config}-f{k}", res, k in spec.image_frames))


def _accuracy(spec: Spec, r: _ConfigRun, state: TaskState, views, k: int, res, drawn: dict) -> dict:
    """Frame k's accuracy, temporal and popping measures against the group's references; ``drawn`` holds the
    frames drawn so far (neighbours a resumed run did not time are added)."""
    tau, renderer = r.cfg.tau, r.renderer
    assert renderer is not None  # r is live: its renderer drew frame k

    def frame(j):
        if j not in drawn:
            drawn[j] = renderer.render(views[j], tau)
        return drawn[j]

    def ref(j):
        return state.reference(spec, r.cfg, j, r.out.images)

    row = frame_accuracy(res, ref(k), flip=spec.flip)
    if k > 0:
        row.update(temporal_errors(frame(k - 1), res, ref(k - 1), ref(k)))
    if 0 < k < spec.frames - 1:
        refs = (ref(k - 1), ref(k), ref(k + 1))
        row.update(popping((frame(k - 1), res, frame(k + 1)), refs, views[k - 1 : k + 2]))
        row["pop_static_px"] = (
            static_pop_pixels(renderer, views[k - 1 : k + 2], refs, tau, res) if np.isfinite(row["pop_px"]) else np.nan
        )
    return row
