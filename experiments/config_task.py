"""One configuration of a spec, run where a GL context lives: draw and time its frames, then measure them.

This is the unit of work of a run, the same whether the run is serial (``experiments.runner``) or spread over
a Dask cluster (``experiments.cluster``): it takes the spec, the configuration and the frames still to do,
and returns plain results (frame rows with their tile rows, images to save, or the error) for the caller to
journal. Datasets are loaded where the task runs, from the spec's paths or names, and kept per process.

Timing is kept apart from measuring: a configuration's frames are all drawn and timed first (results kept
in memory), and only then compared with the references, so the metrics' own threads (FLIP) and the
reference renders never run between timed draws. Each configuration first draws one untimed warm-up frame
(shader compiles, first uploads: one-off costs that are not a frame's); then every frame is drawn ``repeats``
times in a row, all kept in ``wall_ms_repeats`` and their median in ``wall_ms``. Maps for the report's images
come from one more, untimed, draw. A configuration resumed part-way first replays its earlier frames untimed,
so that its GPU tile cache is in the state an uninterrupted run would have.
"""
from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hybrid.camera.view import parse_size
from hybrid.errors import TerrabenchError

from .metrics import frame_accuracy
from .popping import popping, temporal_errors
from .spec import Spec

SETTLE_S = 0.3   # seconds of idle before a configuration's timed frames
MIXED = ("hybrid", "heuristic", "oracle")


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

    config: dict
    frames: list = field(default_factory=list)
    images: list = field(default_factory=list)
    error: dict | None = None
    unreached: int = 0


def group_id(c: dict) -> str:
    """The stem shared by a configuration's paired frames: dataset, seed, flight and size."""
    return f"{Path(str(c['dataset'])).stem}-s{c['seed']}-{Path(str(c['flight'])).stem}-{c['size']}"


class TaskState:
    """What one process keeps between configurations: its GL context, loaded terrains and the references of
    the last group of paired frames (one group at a time, to bound memory)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._terrain: dict = {}
        self._group = None
        self._views = None
        self._refs: dict = {}
        self._reference = None
        self.cost_model = None          # the device's calibrated model, when the client sends one

    def views(self, spec: Spec, c: dict):
        """The group's terrain and views (checked: every eye above the ground); loads the terrain once."""
        from hybrid.camera.clearance import check_eye_above
        from hybrid.camera.flight import get_flight
        from hybrid.reference import ReferenceRenderer
        key = (spec.name, group_id(c))
        if self._group != key:
            self.release_group()
            tkey = (c["dataset"], c["seed"], spec.dataset_size)
            if tkey not in self._terrain:
                self._terrain = {tkey: spec.source(c["dataset"]).load(size=spec.dataset_size or None, seed=c["seed"])}
            hf = self._terrain[tkey]
            w, h = parse_size(c["size"])
            views = get_flight(c["flight"], hf, frames=spec.frames, width=w, height=h).views()
            for k, v in enumerate(views):
                check_eye_above(hf, v, f"flight {c['flight']} frame {k}")
            self._group, self._views = key, (hf, views)
            self._reference = ReferenceRenderer(self.ctx, hf)
        return self._views

    def reference(self, spec: Spec, c: dict, k: int, images: list):
        """The reference render of frame k of the configuration's group (cached for the group)."""
        if k not in self._refs:
            _, views = self.views(spec, c)
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
    return ImageOut(stem, result.colour, result.distance if full else None,
                    dict(getattr(result, "maps", {})) if full else {})


def run_config(spec: Spec, c: dict, todo: list[int], state: TaskState, step=None, fail_fast: bool = False,
               extra: dict | None = None) -> ConfigResult:
    """Draw, time and measure frames ``todo`` of configuration c; ``step(label)`` is called per timed frame and
    ``extra`` columns (device, worker) are added to every row. A failure is returned, not raised (unless
    ``fail_fast``), with the frames it never reached counted."""
    from hybrid.renderer import make_renderer
    out = ConfigResult(c)
    renderer = None
    timed: dict = {}
    try:
        hf, views = state.views(spec, c)
        model = state.cost_model
        renderer = make_renderer(state.ctx, hf, c["policy"], tile_size=spec.tile_size,
                                 reconstruction=c["reconstruction"], budget_bytes=spec.gpu_budget_mib << 20,
                                 upload_budget_ms=spec.upload_budget_ms,
                                 **({"cost_model": model} if model is not None and c["policy"] in MIXED else {}))
        # 1. time every frame first; a short settle lets threads of earlier work go idle, and an untimed
        #    warm-up draw takes the one-off costs (compiles, first uploads) out of the first frame
        for k in range(todo[0]):               # a resumed configuration: its cache as an uninterrupted run's
            renderer.render(views[k], c["tau"])
        time.sleep(SETTLE_S)
        renderer.render(views[todo[0]], c["tau"])
        for k in todo:
            results = [renderer.render(views[k], c["tau"]) for _ in range(spec.repeats)]
            res = results[-1]
            if k in spec.image_frames and c["policy"] in MIXED:
                res = renderer.render(views[k], c["tau"], maps=True)        # untimed, for its maps
            timed[k] = (res, [r.stats.wall_ms for r in results], results[-1].stats)
            if step:
                step(f"{c['config']} frame {k}")
        # 2. then accuracy against the references; neighbours a resumed run did not time are drawn now
        #    (untimed) for the temporal measures
        drawn = {k: v[0] for k, v in timed.items()}

        def frame(j):
            if j not in drawn:
                drawn[j] = renderer.render(views[j], c["tau"])
            return drawn[j]

        def ref(j):
            return state.reference(spec, c, j, out.images)

        for k in todo:
            res, walls, timed_stats = timed[k]                 # counters of a timed draw, not the maps draw
            row = {**c, "frame": k, **timed_stats.row(), **(extra or {}), "wall_ms": float(np.median(walls)),
                   "wall_ms_min": float(np.min(walls)), "wall_ms_max": float(np.max(walls)),
                   "wall_ms_repeats": [float(w) for w in walls], **frame_accuracy(res, ref(k), flip=spec.flip)}
            if k > 0:
                row.update(temporal_errors(frame(k - 1), res, ref(k - 1), ref(k)))
            if 0 < k < spec.frames - 1:
                row.update(popping((frame(k - 1), res, frame(k + 1)), (ref(k - 1), ref(k), ref(k + 1)),
                                   views[k - 1:k + 2]))
            tiles = [{"config": c["config"], "frame": k, "policy": c["policy"], **t} for t in timed_stats.tile_rows]
            out.frames.append((row, tiles))
            if k in spec.image_frames or spec.video:
                out.images.append(_image(f"{c['config']}-f{k}", res, k in spec.image_frames))
    except Exception as exc:  # a failed configuration is returned; the run goes on with the others
        if fail_fast:
            raise
        msg = str(exc) if isinstance(exc, TerrabenchError) else f"{type(exc).__name__}: {exc}"
        out.error = {**c, "error": msg, "trace": traceback.format_exc(limit=4), **(extra or {})}
        out.frames = []
        out.unreached = len([k for k in todo if k not in timed])
    finally:
        if renderer is not None:
            renderer.release()
    return out
