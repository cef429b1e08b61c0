"""`terrabench run SPEC`: every configuration of a spec over the same (paired) views, written as it goes.

Run folder layout (runs/<name>/):
    spec.json, env.json             what was asked and where it ran
    .lock                           held while a run writes here (experiments.runlock): one run at a time
    frames.jsonl                    the journal: one finished frame a line (its row with its tile rows, so
                                    the two are never parted), flushed as it is written
    errors.jsonl                    configurations that failed, with their error; the rest goes on
    frames.parquet, tiles.parquet   the tables, rewritten from the journal after every configuration
    images/                         colour + depth of the spec's image_frames for every configuration
An interrupted run resumes from the journal without redoing finished (configuration, frame) rows; a
configuration resumed part-way first replays its earlier frames untimed, so that its GPU tile cache (and
with it the memory and upload columns) is in the state an uninterrupted run would have. Every table and
image is written under a temporary name and renamed (hybrid.atomic).

Timing is kept apart from measuring: a configuration's frames are all drawn and timed first (results kept
in memory), and only then compared with the references, so the metrics' own threads (FLIP) and the
reference renders never run between timed draws. Each configuration first draws one untimed warm-up frame
(shader compiles, first uploads: one-off costs that are not a frame's); then every frame is drawn ``repeats``
times in a row, all kept in ``wall_ms_repeats`` and their median in ``wall_ms``. Maps for the report's images
come from one more, untimed, draw.
"""
from __future__ import annotations

import errno
import json
import platform
import time
import traceback
from pathlib import Path

import numpy as np
import pandas as pd

from hybrid.atomic import save_npy, save_png, write_json, write_parquet
from hybrid.camera.view import parse_size
from hybrid.errors import TerrabenchError

from .metrics import frame_accuracy
from .popping import popping, temporal_errors
from .progress import Progress
from .runlock import RunLock
from .spec import Spec

SETTLE_S = 0.3   # seconds of idle before a configuration's timed frames


def environment(ctx) -> dict:
    """GL renderer, CPU and package versions of this machine."""
    from importlib import metadata

    from hybrid.gl.context import gl_info
    info = gl_info(ctx)
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import os
    pkgs = {}
    for name in ("terrabench", "moderngl", "numpy", "pandas", "matplotlib", "scikit-image", "flip-evaluator",
                 "fast-simplification", "trimesh"):
        try:
            pkgs[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pkgs[name] = "not installed"
    return {"gl_renderer": info.renderer, "gl_vendor": info.vendor, "gl_version": info.version,
            "cpu": cpu, "cpu_count": os.cpu_count(), "python": platform.python_version(),
            "platform": platform.platform(), "packages": pkgs}


def _jsonable(v):
    if isinstance(v, (np.floating, float)):
        return float(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    return v


class JournalError(TerrabenchError):
    """The run journal cannot be written (disk full, folder gone): the run stops, what was written stays."""


class Journal:
    """Append-only JSON-lines files of a run folder."""

    def __init__(self, folder: Path):
        self.folder = folder

    def rows(self, name: str) -> list[dict]:
        """All rows of a journal file (a torn last line from an interruption is ignored)."""
        p = self.folder / f"{name}.jsonl"
        out = []
        if p.exists():
            for line in p.read_text().splitlines():
                try:
                    out.append(json.loads(line))
                except json.JSONDecodeError:
                    continue
        return out

    def append(self, name: str, rows: list[dict]) -> None:
        """Append rows and flush them to disk."""
        if not rows:
            return
        path = self.folder / f"{name}.jsonl"
        if path.exists() and path.stat().st_size:
            with path.open("rb") as f:                    # an interruption may have left a torn last line
                f.seek(-1, 2)
                torn = f.read(1) != b"\n"
            if torn:
                with path.open("a") as f:
                    f.write("\n")
        text = "".join(json.dumps({k: _jsonable(v) for k, v in r.items()}) + "\n" for r in rows)
        try:
            with path.open("a") as f:          # one write: a kill or a full disk tears at most the last line
                f.write(text)
                f.flush()
        except OSError as exc:
            what = "disk full" if exc.errno == errno.ENOSPC else (exc.strerror or str(exc))
            raise JournalError(f"cannot append to the run journal {path} ({what}); the rows written so far "
                                  "are kept and the run resumes from them") from None

    def append_frame(self, row: dict, tiles: list[dict]) -> None:
        """Append one frame's row together with its tile rows as one journal line."""
        self.append("frames", [{**row, "tiles_rows": [{k: _jsonable(v) for k, v in t.items()} for t in tiles]}])

    def write_tables(self) -> None:
        """Rewrite frames.parquet and tiles.parquet from the journal."""
        frames, tiles = [], []
        for r in self.rows("frames"):
            tiles += r.pop("tiles_rows", [])
            frames.append(r)
        for name, rows in (("frames", frames), ("tiles", tiles)):
            if rows:
                write_parquet(self.folder / f"{name}.parquet", pd.DataFrame(rows))


def failed_configs(folder) -> dict[str, str]:
    """Configurations of a run folder that failed and have not finished since: name -> last error."""
    journal = Journal(Path(folder))
    finished = {r["config"] for r in journal.rows("frames")}
    return {e["config"]: e["error"] for e in journal.rows("errors") if e["config"] not in finished}


def _load_dataset(spec: Spec, label: str, seed: int):
    """The terrain of a spec's dataset label: its file with the entry's loader options, or a named dataset."""
    return spec.source(label).load(size=spec.dataset_size or None, seed=seed)


def _save_image(folder: Path, stem: str, result, full: bool = True) -> None:
    save_png(folder / f"{stem}.png", result.colour)
    if full:
        save_npy(folder / f"{stem}.depth.npy", result.distance)
        for name, arr in getattr(result, "maps", {}).items():
            save_npy(folder / f"{stem}.{name}.npy", arr)


def run_spec(spec: Spec, runs_dir, ctx=None, progress: bool = True, fail_fast: bool = False) -> Path:
    """Run (or resume) every configuration of spec into runs_dir/<name>; returns the run folder."""
    from hybrid.gl.context import shared_context

    runs_dir = Path(runs_dir)
    folder = runs_dir / spec.name
    try:
        (folder / "images").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TerrabenchError(f"cannot create run folder {folder}: {exc.strerror or exc}") from None
    with RunLock(folder):
        ctx = ctx or shared_context()
        old = folder / "spec.json"
        if old.exists() and json.loads(old.read_text()) != json.loads(json.dumps(spec.to_dict())):
            raise TerrabenchError(f"{folder} holds a run of a different spec; choose another name or folder")
        write_json(old, spec.to_dict())
        write_json(folder / "env.json", environment(ctx))
        _run_configs(spec, folder, ctx, progress, fail_fast)
    return folder


def _run_configs(spec: Spec, folder: Path, ctx, progress: bool, fail_fast: bool) -> None:
    """The body of run_spec, under the folder's lock: every configuration not yet in the journal."""
    from hybrid.camera.clearance import check_eye_above
    from hybrid.camera.flight import get_flight
    from hybrid.reference import ReferenceRenderer
    from hybrid.renderer import make_renderer

    journal = Journal(folder)
    done = {(r["config"], r["frame"]) for r in journal.rows("frames")}
    configs = spec.configs()
    bar = Progress(len(configs) * spec.frames, sum(1 for c in configs for k in range(spec.frames)
                                                     if (c["config"], k) in done), progress)
    groups: dict = {}
    for c in configs:
        groups.setdefault((c["dataset"], c["seed"], c["flight"], c["size"]), []).append(c)

    for (ds, seed, fl, size), group in groups.items():
        if all((c["config"], k) in done for c in group for k in range(spec.frames)):
            continue
        w, h = parse_size(size)
        try:
            hf = _load_dataset(spec, ds, seed)
            views = get_flight(fl, hf, frames=spec.frames, width=w, height=h).views()
            for k, v in enumerate(views):
                check_eye_above(hf, v, f"flight {fl} frame {k}")
        except TerrabenchError as exc:
            journal.append("errors", [{**c, "error": str(exc)} for c in group])
            bar.done += len(group) * spec.frames
            continue
        reference = ReferenceRenderer(ctx, hf)
        refs: dict[int, object] = {}
        gid = f"{Path(str(ds)).stem}-s{seed}-{Path(str(fl)).stem}-{size}"

        def ref(k):
            if k not in refs:
                refs[k] = reference.render(views[k], supersample=spec.supersample)
                if k in spec.image_frames or spec.video:
                    _save_image(folder / "images", f"ref-{gid}-f{k}", refs[k], k in spec.image_frames)
            return refs[k]

        for c in group:
            todo = [k for k in range(spec.frames) if (c["config"], k) not in done]
            if not todo:
                continue
            renderer = None
            timed: dict = {}
            try:
                renderer = make_renderer(ctx, hf, c["policy"], tile_size=spec.tile_size,
                                         reconstruction=c["reconstruction"], budget_bytes=spec.gpu_budget_mib << 20,
                                         upload_budget_ms=spec.upload_budget_ms)
                # 1. time every frame first: metric code (FLIP's threads, references) never runs between
                #    a frame's timed draws; a short settle lets threads of earlier work go idle, and an untimed
                #    warm-up draw takes the one-off costs (compiles, first uploads) out of the first frame
                for k in range(todo[0]):       # a resumed configuration: its cache as an uninterrupted run's
                    renderer.render(views[k], c["tau"])
                time.sleep(SETTLE_S)
                renderer.render(views[todo[0]], c["tau"])
                for k in todo:
                    results = [renderer.render(views[k], c["tau"]) for _ in range(spec.repeats)]
                    res = results[-1]
                    if k in spec.image_frames and c["policy"] in ("hybrid", "heuristic", "oracle"):
                        res = renderer.render(views[k], c["tau"], maps=True)     # untimed, for its maps
                    timed[k] = (res, [r.stats.wall_ms for r in results], results[-1].stats)
                    bar.step(f"{c['config']} frame {k}")
                # 2. then accuracy against the references, and the journal; neighbours a resumed run did not
                #    time are drawn now (untimed) for the temporal measures
                drawn = {k: v[0] for k, v in timed.items()}

                def frame(j):
                    if j not in drawn:
                        drawn[j] = renderer.render(views[j], c["tau"])
                    return drawn[j]

                for k in todo:
                    res, walls, timed_stats = timed[k]           # counters of a timed draw, not the maps draw
                    stats = timed_stats.row()
                    row = {**c, "frame": k, **stats, "wall_ms": float(np.median(walls)),
                           "wall_ms_min": float(np.min(walls)), "wall_ms_max": float(np.max(walls)),
                           "wall_ms_repeats": [float(w) for w in walls],
                           **frame_accuracy(res, ref(k), flip=spec.flip)}
                    if k > 0:
                        row.update(temporal_errors(frame(k - 1), res, ref(k - 1), ref(k)))
                    if 0 < k < spec.frames - 1:
                        row.update(popping((frame(k - 1), res, frame(k + 1)), (ref(k - 1), ref(k), ref(k + 1)),
                                           views[k - 1:k + 2]))
                    journal.append_frame(row, [{"config": c["config"], "frame": k, "policy": c["policy"], **t}
                                               for t in timed_stats.tile_rows])
                    if k in spec.image_frames or spec.video:
                        _save_image(folder / "images", f"{c['config']}-f{k}", res, k in spec.image_frames)
            except JournalError:                 # nowhere to record anything: stop with the one message
                raise
            except Exception as exc:  # a failed configuration is recorded; the rest goes on
                if fail_fast:
                    raise
                journal.append("errors", [{**c, "error": f"{type(exc).__name__}: {exc}",
                                           "trace": traceback.format_exc(limit=4)}])
                bar.done += len([k for k in todo if k not in timed])     # frames it never reached
            finally:
                if renderer is not None:
                    renderer.release()
            journal.write_tables()
        reference.release()
    bar.close()
    journal.write_tables()
