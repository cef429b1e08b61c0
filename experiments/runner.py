"""`terrabench run SPEC`: every configuration of a spec over the same (paired) views, written as it goes.

Run folder layout (runs/<name>/):
    spec.json, env.json             what was asked and where it ran
    frames.jsonl, tiles.jsonl       the journal: one finished row a line, flushed as it is written
    errors.jsonl                    configurations that failed, with their error; the rest goes on
    frames.parquet, tiles.parquet   the tables, rewritten from the journal after every configuration
    images/                         colour + depth of the spec's image_frames for every configuration
An interrupted run resumes from the journal without redoing finished (configuration, frame) rows.

Timing is kept apart from measuring: a configuration's frames are all drawn and timed first (results kept
in memory), and only then compared with the references, so the metrics' own threads (FLIP) and the
reference renders never run between timed draws.
"""
from __future__ import annotations

import json
import platform
import time
import traceback
from pathlib import Path

import numpy as np
import pandas as pd

from hybrid.camera.view import parse_size
from hybrid.errors import TerrabenchError

from .metrics import frame_accuracy, temporal_errors
from .progress import Progress
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
        with path.open("a") as f:
            for r in rows:
                f.write(json.dumps({k: _jsonable(v) for k, v in r.items()}) + "\n")
            f.flush()

    def write_tables(self) -> None:
        """Rewrite frames.parquet and tiles.parquet from the journal."""
        for name in ("frames", "tiles"):
            rows = self.rows(name)
            if rows:
                pd.DataFrame(rows).to_parquet(self.folder / f"{name}.parquet", index=False)


def _load_dataset(spec: Spec, label: str, seed: int):
    """The terrain of a spec's dataset label: its file with the entry's loader options, or a named dataset."""
    return spec.source(label).load(size=spec.dataset_size or None, seed=seed)


def _save_image(folder: Path, stem: str, result, full: bool = True) -> None:
    from PIL import Image
    Image.fromarray(result.colour).save(folder / f"{stem}.png")
    if full:
        np.save(folder / f"{stem}.depth.npy", result.distance)
        for name, arr in getattr(result, "maps", {}).items():
            np.save(folder / f"{stem}.{name}.npy", arr)


def run_spec(spec: Spec, runs_dir, ctx=None, progress: bool = True, fail_fast: bool = False) -> Path:
    """Run (or resume) every configuration of spec into runs_dir/<name>; returns the run folder."""
    from hybrid.camera.flight import get_flight
    from hybrid.gl.context import shared_context
    from hybrid.reference import ReferenceRenderer
    from hybrid.renderer import make_renderer

    runs_dir = Path(runs_dir)
    folder = runs_dir / spec.name
    try:
        (folder / "images").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TerrabenchError(f"cannot create run folder {folder}: {exc.strerror or exc}") from None
    ctx = ctx or shared_context()
    old = folder / "spec.json"
    if old.exists() and json.loads(old.read_text()) != json.loads(json.dumps(spec.to_dict())):
        raise TerrabenchError(f"{folder} holds a run of a different spec; choose another name or folder")
    old.write_text(json.dumps(spec.to_dict(), indent=1))
    (folder / "env.json").write_text(json.dumps(environment(ctx), indent=1))
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
                                         reconstruction=c["reconstruction"])
                # 1. time every frame first: metric code (FLIP's threads, references) never runs between
                #    a frame's timed draws; a short settle lets threads of earlier work go idle
                time.sleep(SETTLE_S)
                for k in todo:
                    extra = {"maps": True} if (k in spec.image_frames and
                                               c["policy"] in ("hybrid", "heuristic", "oracle")) else {}
                    results = [renderer.render(views[k], c["tau"]) for _ in range(spec.repeats - 1)]
                    results.append(renderer.render(views[k], c["tau"], **extra))
                    timed[k] = (results[-1], [r.stats.wall_ms for r in results])
                    bar.step(f"{c['config']} frame {k}")
                # 2. then accuracy against the references, and the journal
                for k in todo:
                    res, walls = timed[k]
                    stats = res.stats.row()
                    row = {**c, "frame": k, **stats, "wall_ms": float(np.median(walls)),
                           "wall_ms_min": float(np.min(walls)), **frame_accuracy(res, ref(k), flip=spec.flip)}
                    if k > 0:
                        prev = timed[k - 1][0] if k - 1 in timed else renderer.render(views[k - 1], c["tau"])
                        row.update(temporal_errors(prev, res, ref(k - 1), ref(k)))
                    journal.append("frames", [row])
                    journal.append("tiles", [{"config": c["config"], "frame": k, "policy": c["policy"], **t}
                                             for t in res.stats.tile_rows])
                    if k in spec.image_frames or spec.video:
                        _save_image(folder / "images", f"{c['config']}-f{k}", res, k in spec.image_frames)
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
    return folder
