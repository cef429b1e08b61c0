"""`terrabench report RUN`: reports/<name>/report.md and report.html from a run folder.

The report holds the environment, summary tables per method and scene (frame time, GPU memory, accuracy),
the charts and images, and a short reading generated from the numbers.
"""
from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
import pandas as pd

from hybrid.errors import TerrabenchError

from .charts import all_charts, label_columns
from .spec_datasets import credit_lines
from .tables import md_table


def summary_table(frames: pd.DataFrame) -> pd.DataFrame:
    """Per scene and method: median and p95 frame ms, mean and peak GPU MiB, accuracy means."""
    f = label_columns(frames)
    agg = {"frames": ("frame", "count"), "median_ms": ("wall_ms", "median"),
           "p95_ms": ("wall_ms", lambda s: float(np.percentile(s, 95))),
           "mean_MiB": ("gpu_bytes", lambda s: float(s.mean()) / 2**20),
           "peak_MiB": ("gpu_bytes", lambda s: float(s.max()) / 2**20)}
    for col, name in (("psnr", "psnr_dB"), ("ssim", "ssim"), ("flip", "flip"), ("depth_rel_median", "depth_rel_med"),
                      ("hole_px", "holes_px"), ("coverage_mismatch", "cover_mismatch"), ("error_flicker", "flicker")):
        if col in f:
            fn = "max" if col == "hole_px" else "mean"
            agg[name] = (col, fn)
    t = f.groupby(["scene", "method"]).agg(**agg).reset_index()
    return t.sort_values(["scene", "median_ms"])


def reading(frames: pd.DataFrame, errors: list[dict]) -> list[str]:
    """Sentences stating who won where and by how much, and where methods failed, from the numbers."""
    f = label_columns(frames)
    out = []
    pure = {"raster", "raycast"}
    for sc, g in f.groupby("scene"):
        med = g.groupby("method")["wall_ms"].median().sort_values()
        if len(med) >= 2:
            a, b = med.index[0], med.index[1]
            out.append(f"**{sc}**: fastest is {a} at {med.iloc[0]:.1f} ms median per frame, "
                       f"{med.iloc[1] / med.iloc[0]:.2f}x faster than {b} ({med.iloc[1]:.1f} ms).")
        pol = g.groupby("policy")["wall_ms"].median()
        pures = [p for p in pure if p in pol]
        if "hybrid" in pol and pures:
            best = min(pures, key=lambda p: pol[p])
            ratio = pol[best] / pol["hybrid"]
            word = "faster" if ratio > 1 else "slower"
            out.append(f"  The hybrid is {max(ratio, 1 / ratio):.2f}x {word} than the better pure method ({best}, "
                       f"{pol[best]:.1f} ms vs {pol['hybrid']:.1f} ms)"
                       + (f", and {pol['hybrid'] / pol['oracle']:.2f}x the oracle's time." if "oracle" in pol else "."))
        if "flip" in g and g["flip"].notna().any():
            acc = g.groupby("method")["flip"].mean().sort_values()
            out.append(f"  Most accurate against the reference: {acc.index[0]} (mean FLIP {acc.iloc[0]:.4f}); "
                       f"least: {acc.index[-1]} ({acc.iloc[-1]:.4f}).")
        holes = g.groupby("method")["hole_px"].max()
        bad = holes[holes > 0]
        if len(bad):
            out.append("  Coverage holes against the reference: " +
                       ", ".join(f"{m} up to {int(v)} px" for m, v in bad.items()) + ".")
        for col, what in (("capped_rays", "capped rays"), ("nan_px", "NaN pixels")):
            if col in g and g[col].fillna(0).max() > 0:
                s = g.groupby("method")[col].max()
                out.append(f"  {what}: " + ", ".join(f"{m} {int(v)}" for m, v in s[s > 0].items()) + ".")
    for e in errors:
        out.append(f"Configuration {e.get('config')} failed: {e.get('error')}.")
    return out


def write_report(run: Path, reports_dir: Path = Path("reports"), name: str | None = None, video: bool = False) -> Path:
    """Charts, tables and reading of a run folder into reports_dir/<name>/; returns the report.md path."""
    run = Path(run)
    if not (run / "frames.parquet").exists():
        raise TerrabenchError(f"{run}: not a run folder with results (no frames.parquet); run `terrabench run SPEC` first")
    frames = pd.read_parquet(run / "frames.parquet")
    spec = json.loads((run / "spec.json").read_text())
    env = json.loads((run / "env.json").read_text())
    errors = [json.loads(l) for l in (run / "errors.jsonl").read_text().splitlines()] \
        if (run / "errors.jsonl").exists() else []
    out = Path(reports_dir) / (name or spec["name"])
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TerrabenchError(f"cannot create report folder {out}: {exc.strerror or exc}") from None
    tiles = pd.read_parquet(run / "tiles.parquet") if (run / "tiles.parquet").exists() else None
    charts = all_charts(run, frames, out, spec.get("image_frames", [0]), tiles)
    if video:
        from .video import write_videos
        charts["video"] = write_videos(run, frames, out)
    table = summary_table(frames)
    lines = reading(frames, errors)
    md = [f"# terrabench report: {spec['name']}", "",
          "Every method renders the same camera views (paired flights); accuracy is measured against the "
          f"full-resolution reference image (colour supersampled {spec.get('supersample', 1)}x). Frame time is "
          f"the wall clock around `ctx.finish()`, median of {spec.get('repeats')} repeats.", "",
          "## Environment", "",
          f"- GL renderer: {env['gl_renderer']} ({env['gl_version']})",
          f"- CPU: {env['cpu']} ({env['cpu_count']} cores); Python {env['python']}; {env['platform']}",
          "- Packages: " + ", ".join(f"{k} {v}" for k, v in env["packages"].items()), "",
          "## Spec", "", "```json", json.dumps(spec, indent=1), "```", "",
          "## Reading", ""] + [f"- {l}" if not l.startswith("  ") else f"  - {l.strip()}" for l in lines] + [
          "", "## Summary", "", md_table(table), ""]
    titles = {"frame_time": "Frame time over the flight", "gpu_memory": "GPU memory over the flight",
              "speed_vs_accuracy": "Speed against accuracy", "strategy_mix": "Strategy mix per frame",
              "depth_jump": "Popping: largest depth jump from the previous frame, against the reference's",
              "crossover": "Where each strategy pays: cost per tile against triangles per pixel",
              "images": "Images", "video": "Flight animation"}
    for key, files in charts.items():
        pngs = [p for p in files if p.suffix in (".png", ".gif")]
        if not pngs:
            continue
        md += [f"## {titles[key]}", ""] + [f"![{p.stem}]({p.name})" for p in pngs] + [""]
    credits = credit_lines(spec.get("datasets", []), frames["dataset"].unique())   # the data of this run only
    credits = credits or ["Terrain: synthetic only (seeded, made by terrabench); no data to credit."]
    md += ["---"] + [f"- {c}" for c in credits]
    (out / "report.md").write_text("\n".join(md) + "\n")
    h = ["<!doctype html><html><head><meta charset='utf-8'><title>terrabench report</title>",
         "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:collapse;font-size:12px}"
         "td,th{border:1px solid #ccc;padding:2px 6px}img{max-width:100%}</style></head><body>",
         f"<h1>terrabench report: {html.escape(spec['name'])}</h1>",
         "<h2>Environment</h2><ul>" + "".join(f"<li>{html.escape(str(k))}: {html.escape(str(v))}</li>" for k, v in env.items()) + "</ul>",
         "<h2>Reading</h2><ul>" + "".join(f"<li>{html.escape(l.strip()).replace('**', '')}</li>" for l in lines) + "</ul>",
         "<h2>Summary</h2>", table.to_html(index=False, float_format=lambda v: f"{v:.3g}")]
    for key, files in charts.items():
        pngs = [p for p in files if p.suffix in (".png", ".gif")]
        if pngs:
            h.append(f"<h2>{titles[key]}</h2>" + "".join(f"<p><img src='{p.name}'></p>" for p in pngs))
    h.append("<hr>" + "".join(f"<p>{html.escape(c)}</p>" for c in credits) + "</body></html>")
    (out / "report.html").write_text("\n".join(h))
    return out / "report.md"


def write_run_report(run, reports_dir=Path("reports"), name: str | None = None, video: bool = False) -> Path:
    """The report of any run folder into reports_dir/<name>/: stress.md for a stress run, else report.md + .html."""
    from .folders import writable_folder
    run = Path(run)
    stress = run / "stress.parquet"
    if not stress.exists() and not (run / "frames.parquet").exists():
        raise TerrabenchError(f"{run}: not a run folder with results (no frames.parquet); run `terrabench run SPEC` first")
    writable_folder(Path(reports_dir), "reports folder")
    if stress.exists():
        from .stress import write_stress_report
        return write_stress_report(pd.read_parquet(stress), Path(reports_dir) / (name or run.name))
    return write_report(run, reports_dir, name, video)
