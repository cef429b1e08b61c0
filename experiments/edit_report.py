"""The report of an edit run (kind = "edit"): reports/<name>/report.md and report.html.

Tables per method and edit variant (the static terrain, each brush radius): frame ms, update ms per frame and per
edit, each update step, particles ms, and accuracy against the reference of the same edited heights; the charts
of ``experiments.edit_charts``; a reading generated from the numbers: which method a dynamic scene favours on the
device that ran it, what the ray caster's update costs beside its frame, and whether accuracy held.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
import pandas as pd

from hybrid.atomic import remove_stale_temps, write_text
from hybrid.errors import TerrabenchError

from .edit_charts import STEPS, images_chart, on_off_chart, per_edit, update_chart
from .noise import repeat_matrix, repeat_spread
from .tables import format_number, md_table

TITLES = {
    "update_vs_radius": "Update cost against brush radius",
    "frame_on_off": "Frame time with editing off and on",
    "images": "Images",
}
NOTES = [
    "frame_ms: median over frames of each frame's median of repeats (the draw: planning and drawing, wall clock "
    "around glFinish); update_ms: median over frames of the TerrainEditor's steps for that frame's edits (wall "
    "clock, GL work finished after each GPU step); per_edit_ms: the same per edit; total_ms: median of frame plus "
    "update; particles_ms: median of the particle step and draw (timed apart, not in frame_ms).",
    "cracks_px: most in a frame; coverage_%: the least, over frames, of pixels whose coverage agrees with the "
    "reference's; depth_rel_med: mean over frames of the median relative hit-distance error; flip: mean FLIP. Every "
    "measure is against the reference renderer of the same edited heights, on a draw without particles.",
    "change_ratio: median over frames of the mean colour change from the frame before, over the reference's (1: as "
    "stable as the reference); an edit that made a method pop would raise it above the static variant's.",
]


def variant(radius: float) -> str:
    """An edit variant's label: the brush radius, or static."""
    return f"r{radius:g}m" if radius > 0 else "static"


def summary_table(f: pd.DataFrame) -> pd.DataFrame:
    """Per method and variant: frames, frame, update, total and particles ms, and accuracy."""
    f = f.assign(
        total_ms=f["wall_ms"] + f["update_ms"],
        coverage_pct=100 * (1 - f["coverage_mismatch"]),
        per_edit_ms=f["update_ms"] / f["edits"].where(f["edits"] > 0),
    )
    agg = {
        "frames": ("frame", "count"),
        "frame_ms": ("wall_ms", "median"),
        "update_ms": ("update_ms", "median"),
        "per_edit_ms": ("per_edit_ms", "median"),
        "total_ms": ("total_ms", "median"),
        "particles_ms": ("particles_ms", "median"),
        "cracks_px": ("crack_px", "max"),
        "coverage_%": ("coverage_pct", "min"),
        "depth_rel_med": ("depth_rel_median", "mean"),
    }
    if "flip" in f:
        agg["flip"] = ("flip", "mean")
    if "change_ratio" in f:
        agg["change_ratio"] = ("change_ratio", "median")
    t = f.groupby(["edit_radius", "policy"]).agg(**agg).reset_index()
    t.insert(0, "variant", [variant(r) for r in t["edit_radius"]])
    return t.drop(columns="edit_radius").rename(columns={"policy": "method"})


def steps_table(f: pd.DataFrame) -> pd.DataFrame:
    """Per method and radius: the median ms per edit of each update step (– where the method has no such step)."""
    e = per_edit(f)
    if e.empty:
        return pd.DataFrame()
    cols = [f"{s}_per_edit_ms" for s in STEPS]
    t = e.groupby(["edit_radius", "policy"])[cols].median().reset_index()
    t.insert(0, "variant", [variant(r) for r in t["edit_radius"]])
    t = t.drop(columns="edit_radius").rename(
        columns={"policy": "method", **{c: c.removesuffix("_per_edit_ms") for c in cols}}
    )
    return t.dropna(axis=1, how="all")


def _paired_ratio(a: pd.DataFrame, b: pd.DataFrame) -> tuple[float, float]:
    """(median over the frames both have of a's total ms / b's, the larger repeat spread of the two draws)."""
    ta = a.set_index("frame")["wall_ms"] + a.set_index("frame")["update_ms"]
    tb = b.set_index("frame")["wall_ms"] + b.set_index("frame")["update_ms"]
    both = ta.index.intersection(tb.index)
    ratio = float(np.median(ta[both] / tb[both])) if len(both) else float("nan")
    return ratio, max(repeat_spread(repeat_matrix(a)), repeat_spread(repeat_matrix(b)))


def favour_sentences(f: pd.DataFrame, device: str) -> list[str]:
    """Which method a dynamic scene favours at each radius (least frame plus update, ties within noise named)."""
    out = []
    for radius, g in f[f["editing"]].groupby("edit_radius"):
        totals = g.assign(t=g["wall_ms"] + g["update_ms"]).groupby("policy")["t"].median().sort_values()
        if len(totals) < 2:
            continue
        best, second = totals.index[0], totals.index[1]
        ratio, spread = _paired_ratio(g[g["policy"] == second], g[g["policy"] == best])
        b = g[g["policy"] == best]
        head = (
            f"At a {radius:g} m brush, a dynamic scene on {device} favours **{best}**: "
            f"{format_number(totals[best])} ms a frame with its edit (draw {format_number(b['wall_ms'].median())} "
            f"+ update {format_number(b['update_ms'].median())} ms)"
        )
        if not np.isfinite(ratio) or abs(ratio - 1) <= spread:
            out.append(
                f"{head}, within noise of {second} ({format_number(totals[second])} ms; repeats spread "
                f"{100 * spread:.0f} %): a tie."
            )
        else:
            out.append(
                f"{head}, {ratio:.2f}x faster than the next, {second} ({format_number(totals[second])} ms); "
                f"slowest {totals.index[-1]} ({format_number(totals.iloc[-1])} ms)."
            )
    static = f[~f["editing"]].groupby("policy")["wall_ms"].median().sort_values()
    if len(static):
        out.append(
            f"On the static terrain the fastest draw is {static.index[0]} ({format_number(static.iloc[0])} ms"
            + (f"; then {static.index[1]}, {format_number(static.iloc[1])} ms" if len(static) > 1 else "")
            + ")."
        )
    return out


def share_sentence(f: pd.DataFrame) -> str:
    """What an edit a frame adds to each method's frame, as a share of its static frame time, per radius."""
    static = f[~f["editing"]].groupby("policy")["wall_ms"].median()
    parts = []
    for radius, g in f[f["editing"]].groupby("edit_radius"):
        upd = g.groupby("policy")["update_ms"].median()
        shares = ", ".join(f"{p} {100 * upd[p] / static[p]:.0f} %" for p in upd.index if p in static)
        parts.append(f"{radius:g} m: {shares}")
    return "An edit a frame costs, beside each method's static frame time: " + "; ".join(parts) + "." if parts else ""


def step_sentence(f: pd.DataFrame) -> str:
    """Each method's largest update step at the largest radius, and its share of that method's update."""
    e = per_edit(f)
    if e.empty:
        return ""
    e = e[e["edit_radius"] == e["edit_radius"].max()]
    parts = []
    for p, g in e.groupby("policy"):
        steps = {s: float(g[f"{s}_per_edit_ms"].median()) for s in STEPS if g[f"{s}_per_edit_ms"].notna().any()}
        top = max(steps, key=lambda s: steps[s])
        parts.append(f"{p}: {top} {format_number(steps[top])} of {format_number(g['update_per_edit_ms'].median())} ms")
    return f"The largest update step at {e['edit_radius'].max():g} m, per edit: " + "; ".join(parts) + "."


def accuracy_sentence(f: pd.DataFrame) -> str:
    """Whether accuracy after edits kept its static level: cracks, coverage and each method's median depth error."""
    e, s = f[f["editing"]], f[~f["editing"]]
    if e.empty or "crack_px" not in f:
        return ""
    depth = []
    for p, g in e.groupby("policy"):
        st = s.loc[s["policy"] == p, "depth_rel_median"].mean()
        depth.append(f"{p} {format_number(g['depth_rel_median'].mean())} (static {format_number(st)})")
    return (
        f"Against the reference of the edited heights: {int(e['crack_px'].max())} crack pixels in any edited "
        f"frame (static: {int(s['crack_px'].max()) if len(s) else 0}); coverage agrees on at least "
        f"{100 * (1 - e['coverage_mismatch'].max()):.2f} % of pixels (static: "
        f"{100 * (1 - s['coverage_mismatch'].max()):.2f} %); median relative depth error, mean over edited "
        f"frames: {', '.join(depth)}."
    )


def stability_sentence(f: pd.DataFrame) -> str:
    """Whether edits made a method change more between frames than the reference did: each method's median
    change ratio over edited frames against the static variant's."""
    if "change_ratio" not in f or f["change_ratio"].isna().all():
        return ""
    e, s = f[f["editing"]], f[~f["editing"]]
    parts = []
    for p, g in e.groupby("policy"):
        st = s.loc[s["policy"] == p, "change_ratio"].median()
        parts.append(f"{p} {g['change_ratio'].median():.3f} (static {st:.3f})")
    return (
        "Frame-to-frame colour change over the reference's (1: as stable as the reference), median over edited "
        f"frames: {', '.join(parts)}."
    )


def particles_sentence(f: pd.DataFrame) -> str:
    """What the particles cost a frame, apart from it."""
    n = int(f["particles"].max())
    if not n:
        return "No particles."
    return (
        f"{n} particles cost {format_number(f['particles_ms'].median())} ms a frame apart from the draw (step "
        f"{format_number(f['particles_step_ms'].median())} ms, draw {format_number(f['particles_draw_ms'].median())}"
        f" ms, medians over every frame and method)."
    )


def reading(f: pd.DataFrame, env: dict, errors: list[dict]) -> list[str]:
    """The generated reading of an edit run."""
    device = env.get("gl_renderer", "this device")
    lines = favour_sentences(f, device) + [
        share_sentence(f),
        step_sentence(f),
        accuracy_sentence(f),
        stability_sentence(f),
        particles_sentence(f),
    ]
    lines.append("Timings are indicative: one run, wall clock on a machine possibly shared with other work.")
    if errors:
        lines.append(
            f"{len({e.get('config') for e in errors})} configuration(s) failed: "
            + "; ".join(f"{e.get('config')}: {str(e.get('error', '')).splitlines()[0]}" for e in errors[:3])
        )
    return [x for x in lines if x]


def _deformation(p: dict) -> str:
    """A sentence on the programme's deformation, or nothing where it names none."""
    d = p.get("deformation")
    if not d:
        return ""
    return (
        f" A {d['kind']} of radius {d['radius']:g} m runs from {d['start']:g} s to {d['end']:g} s under every edited "
        f"terrain, {d['seconds_per_frame']:g} s a frame."
    )


def _markdown(spec: dict, env: dict, lines: list[str], tables: dict, charts: dict) -> str:
    p = spec["edit"]
    md = (
        [
            f"# terrabench edit report: {spec['name']}",
            "",
            f"Every method follows the same edits over the same views ({spec['flight']} flight, {spec['frames']} frames, "
            f"{spec['sizes'][0]}): {p['edits_per_frame']} {p['brush']} a frame of strength {p['strength']:g} along "
            f"a path of {len(p['path'])} way-points, at radii {', '.join(f'{r:g}' for r in p['radii'])} m, and the "
            f"static terrain; {p['particles']} particles fall and bounce on it.{_deformation(p)} Frame time is the "
            f"median of {spec['repeats']} timed draws after the edits, configurations timed in rotating turns.",
            "",
            "## Environment",
            "",
            f"- GL renderer: {env['gl_renderer']} ({env['gl_version']})",
            f"- CPU: {env['cpu']} ({env['cpu_count']} cores); Python {env['python']}; {env['platform']}",
            "",
            "## Reading",
            "",
        ]
        + [f"- {x}" for x in lines]
        + [""]
    )
    for title, t in tables.items():
        md += [f"## {title}", "", md_table(t.map(format_number) if len(t) else t), ""]
    md += [f"- {n}" for n in NOTES] + [""]
    for key, files in charts.items():
        md += [f"## {TITLES[key]}", ""] + [f"![{q.stem}]({q.name})" for q in files if q.suffix == ".png"] + [""]
    md += ["## Spec", "", "```json", json.dumps(spec, indent=1), "```", ""]
    return "\n".join(md)


def _html(spec: dict, env: dict, lines: list[str], tables: dict, charts: dict) -> str:
    from .report_html import CSS, chart_html, environment_html, inline, reading_html, table_html

    title = f"terrabench edit report: {spec['name']}"
    body = [f"<h1>{html.escape(title)}</h1>", "<h2 id='reading'>Reading</h2>", reading_html(lines)]
    body += [f"<h2>{html.escape(t)}</h2>" + table_html(df) for t, df in tables.items()]
    body += ["<ul class='note'>" + "".join(f"<li>{inline(n)}</li>" for n in NOTES) + "</ul>"]
    body += [chart_html(TITLES[k], v, k) for k, v in charts.items()]
    body += [
        "<h2 id='method'>Environment</h2>",
        environment_html(env, spec),
        "<details><summary>Spec (spec.json)</summary><pre>"
        + html.escape(json.dumps(spec, indent=1), quote=False)
        + "</pre></details>",
    ]
    return (
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"<title>{html.escape(title)}</title><style>{CSS}</style></head><body>\n"
        + "\n".join(body)
        + "\n</body></html>\n"
    )


def write_edit_report(run: Path, reports_dir: Path = Path("reports"), name: str | None = None) -> Path:
    """Tables, charts and reading of an edit run folder into reports_dir/<name>/; returns the report.md path."""
    from .folders import read_json, read_parquet
    from .journal import Journal

    run = Path(run)
    if not (run / "frames.parquet").exists():
        raise TerrabenchError(f"{run}: not a run folder with results (no frames.parquet); run `terrabench run` first")
    f = read_parquet(run / "frames.parquet", "run table")
    spec, env = read_json(run / "spec.json", "run spec"), read_json(run / "env.json", "run environment")
    out = Path(reports_dir) / (name or spec["name"])
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TerrabenchError(f"cannot create report folder {out}: {exc.strerror or exc}") from None
    remove_stale_temps(out)
    charts = {
        "update_vs_radius": update_chart(f, out),
        "frame_on_off": on_off_chart(f, out),
        "images": images_chart(run, f, out, max(spec.get("image_frames", [0]))),
    }
    charts = {k: v for k, v in charts.items() if v}
    tables = {
        "Summary per method and edit variant": summary_table(f),
        "Update steps (median ms per edit)": steps_table(f),
    }
    tables = {k: v for k, v in tables.items() if len(v)}
    lines = reading(f, env, Journal(run).rows("errors"))
    write_text(out / "report.md", _markdown(spec, env, lines, tables, charts))
    write_text(out / "report.html", _html(spec, env, lines, tables, charts))
    return out / "report.md"
