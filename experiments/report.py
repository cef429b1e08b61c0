"""`terrabench report RUN`: reports/<name>/report.md and report.html from a run folder.

The report holds the environment, summary tables per method and scene (frame time, GPU memory, accuracy),
the charts and images, and a short reading generated from the numbers.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from hybrid.atomic import remove_stale_temps, write_text
from hybrid.errors import TerrabenchError

from .adapt_charts import convergence_chart, gpu_cpu_chart
from .charts import all_charts, label_columns
from .environment import adaptation_line, cost_model_line
from .reading import reading
from .report_html import page
from .report_html_headline import scene_headlines
from .spec import Spec
from .spec_datasets import credit_lines
from .tables import md_table


def summary_table(frames: pd.DataFrame) -> pd.DataFrame:
    """Per scene and method: median and p95 frame ms, the repeats' spread (noise, %), CPU ms, GPU ms (where the GL
    times it), mean and peak GPU MiB,
    accuracy over terrain pixels, cracks, silhouette differences, reference terrain drawn as sky, popping."""
    from .noise import repeat_matrix, repeat_spread

    f = label_columns(frames)
    agg = {
        "frames": ("frame", "count"),
        "median_ms": ("wall_ms", "median"),
        "p95_ms": ("wall_ms", lambda s: float(np.percentile(s, 95))),
        **({"cpu_ms": ("cpu_ms", "median")} if "cpu_ms" in f else {}),
        **({"gpu_ms": ("gpu_ms", "median")} if "gpu_ms" in f and f["gpu_ms"].notna().any() else {}),
        "mean_MiB": ("gpu_bytes", lambda s: float(s.mean()) / 2**20),
        "peak_MiB": ("gpu_bytes", lambda s: float(s.max()) / 2**20),
    }
    for col, name, fn in (
        ("psnr", "psnr_dB", "mean"),
        ("ssim", "ssim", "mean"),
        ("flip", "flip", "mean"),
        ("depth_rel_median", "depth_rel_med", "mean"),
        ("depth_rel_p99", "depth_rel_p99", "max"),
        ("crack_px", "cracks_px", "max"),
        ("silhouette_px", "silhouette_px", "mean"),
        ("terrain_as_sky", "sky_for_terrain_%", "mean"),
        ("pop_px", "pop_px", lambda s: s.sum(min_count=1)),
        ("pop_static_px", "pop_static_px", lambda s: s.sum(min_count=1)),
        ("error_flicker", "flicker", "mean"),
    ):
        if col in f:
            agg[name] = (col, fn)
    t = f.groupby(["scene", "method"]).agg(**agg).reset_index()
    if "sky_for_terrain_%" in t:
        t["sky_for_terrain_%"] *= 100
    noise = {k: 100 * repeat_spread(repeat_matrix(g)) for k, g in f.groupby(["scene", "method"])}
    t.insert(4, "noise_%", [noise[(sc, m)] for sc, m in zip(t["scene"], t["method"])])
    return t.sort_values(["scene", "median_ms"])


MEASURES = [
    "median_ms: median over frames of each frame's median of repeats; noise_%: the median spread (max - min) / "
    "median of a frame's repeats, the noise the reading weighs differences against (with a bootstrap interval of "
    "the ratio over frames and repeats); cpu_ms: median over frames of the CPU's share of a frame, planning plus "
    "issuing its GL commands (waits for the GL left out; on llvmpipe issuing includes vertex, geometry and "
    "compute work, which run inside the calls, but not fragment work); gpu_ms: median over frames of the GL timer "
    "query's time of a frame's drawing, a column only where the GL has the query (not on llvmpipe).",
    "psnr_dB, ssim, flip: over the pixels where the method or the reference shows terrain (identical sky left "
    "out); depth_rel_med: relative hit-distance error over the pixels both cover, mean over frames of its median; "
    "depth_rel_p99: the largest of the frames' 99th percentiles.",
    "cracks_px (most in a frame): sky enclosed by the method's own terrain (within 3 px both sides, across or "
    "along) where the reference has terrain more than 2 px from its sky; silhouette_px (mean a frame): every other "
    "pixel where method and reference disagree on terrain; sky_for_terrain_%: the reference's terrain pixels the "
    "method draws as sky.",
    "pop_px (sum over the flight): pixels whose relative depth error steps by more than 0.1 % in one frame "
    "beyond the camera's steady motion (second difference over three frames, patches of 5 x 5 px); measured only "
    "where the terrain moves at most 2 px a frame across the image (e.g. the dolly flight), else –; "
    "pop_static_px: the same with each frame's level of detail held over its three (tiles, strategies and leaves "
    "as the middle frame drew them), what the measure flags on a mesh that does not switch: popping is pop_px "
    "beyond it.",
]


NO_ACCURACY = "accuracy not measured (accuracy = false): no reference image, timing only"


def measures(accuracy: bool) -> list[str]:
    """The summary's column notes: the timing ones, and the accuracy ones where accuracy was measured."""
    return MEASURES if accuracy else MEASURES[:1]


def intro(spec: dict) -> str:
    """The report's first paragraph: what is compared with what, and how frames are timed."""
    accuracy = (
        (
            "accuracy is measured against the full-resolution reference image (colour supersampled "
            f"{spec.get('supersample', 1)}x)"
        )
        if spec.get("accuracy", True)
        else NO_ACCURACY
    )
    return (
        f"Every method renders the same camera views (paired flights); {accuracy}. Frame time is the wall clock "
        f"around `ctx.finish()`, median of {spec.get('repeats')} repeats after one untimed warm-up frame per "
        "configuration; the methods of a scene and tau are timed interleaved, each repeat of a frame drawn by "
        "every method in turn, so a drift of the machine falls on all alike; the reading calls a difference "
        "within the noise of this run a tie."
    )


def missing_frames(spec: dict, frames: pd.DataFrame) -> str:
    """What a run folder lacks of its spec's (configuration, frame) rows, in words; empty when complete."""
    try:
        expected = Spec(**{k: v for k, v in spec.items() if k in Spec.__dataclass_fields__}).configs()
    except (TypeError, TerrabenchError):
        return ""  # a spec of another form: nothing to compare with
    have = set(zip(frames["config"], frames["frame"]))
    n = int(spec.get("frames", 1))
    gaps = {c.config: n - sum((c.config, k) in have for k in range(n)) for c in expected}
    gaps = {k: v for k, v in gaps.items() if v}
    if not gaps:
        return ""
    total = len(expected) * n
    named = ", ".join(f"{k} ({v} of {n} frames)" for k, v in list(gaps.items())[:5])
    more = f" and {len(gaps) - 5} more" if len(gaps) > 5 else ""
    return (
        f"{sum(gaps.values())} of {total} frames are missing, in {len(gaps)} of {len(expected)} configurations: "
        f"{named}{more}. Resume with `terrabench run` on the same spec, or read this report as partial."
    )


TITLES = {
    "frame_time": "Frame time over the flight",
    "gpu_memory": "GPU memory over the flight",
    "speed_vs_accuracy": "Speed against accuracy",
    "strategy_mix": "Strategy mix per frame",
    "convergence": "Convergence: the hybrid's frame time and prediction error as its model learns",
    "gpu_vs_cpu": "GPU time against CPU time per frame",
    "popping": "Popping: pixels whose depth error steps in one frame",
    "crossover": "Where each strategy pays: cost per tile against triangles per pixel",
    "images": "Images",
    "video": "Flight animation",
}


def _read_run(run: Path) -> tuple[pd.DataFrame, dict, dict, list[dict]]:
    """A run folder's frames, spec, environment and failures."""
    if not (run / "frames.parquet").exists():
        raise TerrabenchError(
            f"{run}: not a run folder with results (no frames.parquet); run `terrabench run SPEC` first"
        )
    from .folders import read_json, read_parquet
    from .journal import Journal

    errors = Journal(run).rows("errors")
    return (
        read_parquet(run / "frames.parquet", "run table"),
        read_json(run / "spec.json", "run spec"),
        read_json(run / "env.json", "run environment"),
        errors,
    )


def _charts(run: Path, frames: pd.DataFrame, spec: dict, out: Path, video: bool) -> dict[str, list[Path]]:
    """Every chart of the report into out, by name in the order they appear."""
    from .folders import read_parquet

    tiles = read_parquet(run / "tiles.parquet", "run table") if (run / "tiles.parquet").exists() else None
    charts = all_charts(run, frames, out, spec.get("image_frames", [0]), tiles)
    f = label_columns(frames)
    later = {k: charts.pop(k) for k in ("popping", "crossover", "images")}  # the adaptation charts go before
    charts.update(convergence=convergence_chart(f, out), gpu_vs_cpu=gpu_cpu_chart(f, out), **later)
    if video:
        from .video import write_videos

        charts["video"] = write_videos(run, frames, out)
    return charts


def _markdown(
    title: str,
    missing: str,
    spec: dict,
    env: dict,
    lines: list[str],
    table: pd.DataFrame,
    charts: dict,
    credits: list[str],
) -> str:
    """The report as Markdown."""
    measured = spec.get("accuracy", True)
    md = (
        [f"# {title}", ""]
        + ([f"**Incomplete:** {missing}", ""] if missing else [])
        + [
            intro(spec),
            "",
            "## Environment",
            "",
            f"- GL renderer: {env['gl_renderer']} ({env['gl_version']})",
            f"- CPU: {env['cpu']} ({env['cpu_count']} cores); Python {env['python']}; {env['platform']}",
            "- Packages: " + ", ".join(f"{k} {v}" for k, v in env["packages"].items()),
            f"- Hybrid cost model: {cost_model_line(env)}",
            f"- Hybrid adapted: {adaptation_line(spec)}",
            "",
            "## Spec",
            "",
            "```json",
            json.dumps(spec, indent=1),
            "```",
            "",
            "## Reading",
            "",
        ]
        + [f"- {l}" if not l.startswith("  ") else f"  - {l.strip()}" for l in lines]
        + ["", "## Summary", "", md_table(table), ""]
        + [f"- {m}" for m in measures(measured)]
        + [""]
    )
    for key, files in charts.items():
        pngs = [p for p in files if p.suffix in (".png", ".gif")]
        if pngs:
            md += [f"## {TITLES[key]}", ""] + [f"![{p.stem}]({p.name})" for p in pngs] + [""]
    md += ["---"] + [f"- {c}" for c in credits]
    return "\n".join(md) + "\n"


def write_report(run: Path, reports_dir: Path = Path("reports"), name: str | None = None, video: bool = False) -> Path:
    """Charts, tables and reading of a run folder into reports_dir/<name>/; returns the report.md path."""
    run = Path(run)
    frames, spec, env, errors = _read_run(run)
    out = Path(reports_dir) / (name or spec["name"])
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TerrabenchError(f"cannot create report folder {out}: {exc.strerror or exc}") from None
    remove_stale_temps(out)  # what a killed report left
    charts = _charts(run, frames, spec, out, video)
    table = summary_table(frames)
    lines = reading(frames, errors) + ([] if spec.get("accuracy", True) else [NO_ACCURACY])
    missing = missing_frames(spec, frames)
    title = f"terrabench report: {spec['name']}" + (" (INCOMPLETE RUN)" if missing else "")
    credits = credit_lines(spec.get("datasets", []), frames["dataset"].unique())  # the data of this run only
    credits = credits or ["Terrain: synthetic only (seeded, made by terrabench); no data to credit."]
    parts = (title, missing, spec, env, lines, table, charts, credits)
    write_text(out / "report.md", _markdown(*parts))
    notes = measures(spec.get("accuracy", True))
    write_text(out / "report.html", page(*parts, scene_headlines(frames), intro(spec), notes, TITLES))
    return out / "report.md"


def _kind(run: Path) -> str:
    """The kind of spec a run folder ran ("flights" when its spec.json names none or is missing)."""
    from .folders import read_json

    spec = run / "spec.json"
    return str(read_json(spec, "run spec").get("kind", "flights")) if spec.exists() else "flights"


def write_run_report(run, reports_dir=Path("reports"), name: str | None = None, video: bool = False) -> Path:
    """The report of any run folder into reports_dir/<name>/: stress.md for a stress run, else report.md + .html
    (an edit run's from ``experiments.edit_report``)."""
    from .folders import writable_folder

    run = Path(run)
    stress = run / "stress.parquet"
    if not stress.exists() and not (run / "frames.parquet").exists():
        raise TerrabenchError(
            f"{run}: not a run folder with results (no frames.parquet); run `terrabench run SPEC` first"
        )
    writable_folder(Path(reports_dir), "reports folder")
    if _kind(run) == "edit":
        from .edit_report import write_edit_report

        return write_edit_report(run, Path(reports_dir), name)
    if stress.exists():
        from .folders import read_parquet
        from .stress_report import write_stress_report

        return write_stress_report(read_parquet(stress, "stress table"), Path(reports_dir) / (name or run.name))
    return write_report(run, reports_dir, name, video)
