"""The report as one self-contained HTML page (inline CSS, images beside it), ordered for a person reading it.

First the headline per scene (the fastest method, the hybrid against the better pure method with its interval,
the most accurate method), then the speed-against-accuracy chart, then the details: the reading with its
nesting, the summary tables per scene (each in its own scrolling box), the other charts, and how the run was
measured (method, environment as a key/value table, spec). Missing values show as '–', never NaN.
"""

from __future__ import annotations

import html
import json
import re

import pandas as pd

from .environment import adaptation_line, cost_model_line
from .report_html_headline import SceneHeadline
from .tables import format_number

TOP_CHART = ("speed_vs_accuracy", "frame_time")  # the first of these a run has goes near the top

CSS = """
*{box-sizing:border-box}
body{font:15px/1.5 system-ui,-apple-system,'Segoe UI',sans-serif;color:#1d1f24;max-width:1240px;margin:0 auto;
 padding:0 24px 48px;overflow-wrap:anywhere}
h1{font-size:26px;margin:24px 0 4px}h2{font-size:20px;margin:36px 0 10px;border-bottom:1px solid #dde;padding-bottom:4px}
h3{font-size:16px;margin:0 0 8px}
nav{font-size:13px;color:#555;margin-bottom:16px}nav a{margin-right:14px;color:#2456b5;text-decoration:none}
.incomplete{background:#fff4e0;border-left:4px solid #e08a00;padding:8px 12px}
.cards{display:grid;grid-template-columns:repeat(auto-fit,minmax(340px,1fr));gap:14px}
.card{border:1px solid #d8dbe3;border-radius:8px;padding:12px 14px;background:#fafbfd}
.card ul{margin:4px 0;padding-left:18px}.card li{margin:2px 0}
.label{color:#555;font-size:13px;text-transform:uppercase;letter-spacing:.04em}
.win{color:#17753a;font-weight:600}.loss{color:#b3261e;font-weight:600}.tie{color:#6b6f78;font-weight:600}
.ties,.note{color:#555;font-size:13px}
figure{margin:12px 0}figure img,p img{max-width:100%;height:auto;display:block}
.reading li{margin:4px 0}.reading ul ul{font-size:14px;color:#333}
.scroll{overflow-x:auto;max-width:100%;margin:8px 0 16px;border:1px solid #e2e4ea;border-radius:6px}
table{border-collapse:collapse;font-size:12.5px}caption{text-align:left;font-weight:600;padding:6px 8px}
th,td{border-bottom:1px solid #e6e8ee;padding:3px 8px;white-space:nowrap;text-align:left}
td.num{text-align:right;font-variant-numeric:tabular-nums}th{background:#f1f3f7}
tr>:first-child{position:sticky;left:0;background:#fff}tr>th:first-child{background:#f1f3f7}
table.kv td:first-child,table.kv th{white-space:nowrap;vertical-align:top;font-weight:600}
table.kv td{white-space:normal}
ul.compact{list-style:none;padding:0;margin:0;display:flex;flex-wrap:wrap;gap:4px 14px}
pre{overflow-x:auto;background:#f6f7f9;padding:10px;border-radius:6px;font-size:12px}
code{background:#f1f3f7;padding:0 3px;border-radius:3px}
footer{margin-top:36px;color:#555;font-size:13px;border-top:1px solid #dde}
"""


def inline(text: str) -> str:
    """Markdown-ish text as safe HTML: escaped, with **bold** and `code` kept."""
    s = html.escape(text.strip(), quote=False)
    s = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", s)
    return re.sub(r"`(.+?)`", r"<code>\1</code>", s)


def reading_html(lines: list[str]) -> str:
    """The reading as nested lists: an indented line belongs to the unindented line above it."""
    out, open_sub = ["<ul class='reading'>"], False
    for i, line in enumerate(lines):
        child = line.startswith("  ") and i > 0
        if child and not open_sub:
            out[-1] = out[-1].removesuffix("</li>")  # reopen the parent item to nest under it
            out.append("<ul>")
            open_sub = True
        elif not child and open_sub:
            out.append("</ul></li>")
            open_sub = False
        out.append(f"<li>{inline(line)}</li>")
    out.append("</ul></li></ul>" if open_sub else "</ul>")
    return "".join(out)


def value_html(v) -> str:
    """A value of env.json as HTML: a dict as a compact 'key value' list (nested dicts likewise), a list
    comma-joined, anything else as escaped text."""
    if isinstance(v, dict):
        items = "".join(f"<li><b>{html.escape(str(k))}</b> {value_html(x)}</li>" for k, x in v.items())
        return f"<ul class='compact'>{items}</ul>"
    if isinstance(v, (list, tuple)):
        return ", ".join(value_html(x) for x in v) or "–"
    return "–" if v is None or v == "" else html.escape(str(v))


ENV_LABELS = {
    "gl_renderer": "GL renderer",
    "gl_vendor": "GL vendor",
    "gl_version": "GL version",
    "cpu": "CPU",
    "cpu_count": "CPU cores",
    "python": "Python",
    "platform": "Platform",
    "packages": "Packages",
    "scheduler": "Dask scheduler",
    "workers": "Workers",
}


def environment_html(env: dict, spec: dict) -> str:
    """Where the run ran, as a key/value table: GL, CPU, Python, packages, the hybrid's cost model and adaptation."""
    rows = [
        (ENV_LABELS.get(k, k.replace("_", " ").capitalize()), value_html(v))
        for k, v in env.items()
        if k != "cost_model"
    ]
    rows += [
        ("Hybrid cost model", html.escape(cost_model_line(env))),
        ("Hybrid adapted", html.escape(adaptation_line(spec))),
    ]
    body = "".join(f"<tr><td>{html.escape(k)}</td><td>{v}</td></tr>" for k, v in rows)
    return f"<div class='scroll'><table class='kv'><tbody>{body}</tbody></table></div>"


def table_html(df: pd.DataFrame, caption: str = "") -> str:
    """A table in its own horizontally scrolling box: numbers to three significant digits, '–' where missing."""
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in df.columns)
    body = []
    for row in df.itertuples(index=False):
        cells = []
        for v in row:
            num = (isinstance(v, (int, float)) and not isinstance(v, bool)) or hasattr(v, "dtype")
            text = "–" if v is None or (num and pd.isna(v)) else format_number(v)
            cells.append(f"<td class='num'>{text}</td>" if num else f"<td>{html.escape(text)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    return f"<div class='scroll'><table>{cap}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table></div>"


def summary_html(table: pd.DataFrame) -> str:
    """The summary as one table per scene (the scene as caption, not a column), fastest method first."""
    if "scene" not in table:
        return table_html(table)
    return "".join(table_html(g.drop(columns="scene"), str(sc)) for sc, g in table.groupby("scene", sort=False))


def _names(items: list[str]) -> str:
    return ", ".join(f"<b>{html.escape(m)}</b>" for m in items)


def headline_card(h: SceneHeadline) -> str:
    """One scene's card: fastest (and who ties with it), hybrid against the better pure method, most accurate."""
    tied = ""
    if h.tied:
        shown = ", ".join(f"{html.escape(m)} ({ms:.1f} ms)" for m, ms in h.tied[:4])
        more = f" and {len(h.tied) - 4} more" if len(h.tied) > 4 else ""
        tied = f"<div class='ties'>within noise of it: {shown}{more}</div>"
    parts = [
        f"<div class='card'><h3>{html.escape(h.scene)}</h3>",
        (
            f"<div class='label'>Fastest</div><div><b>{html.escape(h.fastest)}</b>, {h.fastest_ms:.1f} ms median "
            f"a frame</div>{tied}"
        ),
        "<div class='label'>Hybrid against the better pure method</div>",
    ]
    if h.gains:
        parts.append(
            "<ul>"
            + "".join(
                f"<li>{html.escape(g.hybrid)} ({g.cmp.ms_a:.1f} ms) against {html.escape(g.pure)} ({g.cmp.ms_b:.1f} ms): "
                f"<span class='{g.verdict}'>{html.escape(g.words())}</span></li>"
                for g in h.gains
            )
            + "</ul>"
        )
    else:
        parts.append("<div class='ties'>no hybrid in this scene</div>")
    if h.accurate:
        parts.append(
            f"<div class='label'>Most accurate</div><div>{_names(h.accurate)} "
            f"(mean FLIP {h.flip:.4f} over terrain pixels)</div>"
        )
    return "".join(parts) + "</div>"


def headline_html(headlines: list[SceneHeadline]) -> str:
    """The headline section: one card per scene and a line on how to read the intervals."""
    note = (
        "<p class='note'>Times are medians over a flight's frames of each frame's median of repeats; intervals "
        "are 95 % bootstrap intervals of the ratio over frames and repeats; a difference within the run's noise "
        "is called a tie (see <a href='#method'>How it was measured</a>).</p>"
    )
    return (
        "<h2 id='headline'>Answer per scene</h2><div class='cards'>"
        + "".join(headline_card(h) for h in headlines)
        + "</div>"
        + note
    )


def chart_html(title: str, files: list, key: str, lazy: bool = True) -> str:
    """A chart section: its title and every PNG or GIF of it, relative to the report."""
    imgs = [p for p in files if p.suffix in (".png", ".gif")]
    if not imgs:
        return ""
    load = " loading='lazy'" if lazy else ""
    figs = "".join(
        f"<figure><img src='{html.escape(p.name)}' alt='{html.escape(p.stem)}'{load}></figure>" for p in imgs
    )
    return f"<h2 id='{key}'>{html.escape(title)}</h2>{figs}"


def page(
    title: str,
    missing: str,
    spec: dict,
    env: dict,
    lines: list[str],
    table: pd.DataFrame,
    charts: dict,
    credits: list[str],
    headlines: list[SceneHeadline],
    intro: str,
    notes: list[str],
    titles: dict,
) -> str:
    """The whole report page; charts maps name -> files in report order, titles name -> heading."""
    top = next((k for k in TOP_CHART if any(p.suffix == ".png" for p in charts.get(k, []))), None)
    rest = "".join(chart_html(titles[k], v, k) for k, v in charts.items() if k != top)
    nav = [
        ("headline", "Answer"),
        (top, titles.get(top, "")),
        ("reading", "Reading"),
        ("summary", "Summary"),
        ("method", "How it was measured"),
    ]
    h = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width, initial-scale=1'>",
        f"<title>{html.escape(title)}</title><style>{CSS}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        "<nav>" + "".join(f"<a href='#{k}'>{html.escape(t)}</a>" for k, t in nav if k) + "</nav>",
        f"<p class='incomplete'><b>Incomplete:</b> {inline(missing)}</p>" if missing else "",
        headline_html(headlines),
        chart_html(titles[top], charts[top], top, lazy=False) if top else "",
        "<h2 id='reading'>Reading</h2>",
        reading_html(lines),
        "<h2 id='summary'>Summary per scene</h2>",
        summary_html(table),
        "<ul class='note'>" + "".join(f"<li>{inline(m)}</li>" for m in notes) + "</ul>",
        rest,
        "<h2 id='method'>How it was measured</h2>",
        f"<p>{inline(intro)}</p>",
        "<h3>Environment</h3>",
        environment_html(env, spec),
        "<details><summary>Spec (spec.json)</summary><pre>"
        + html.escape(json.dumps(spec, indent=1), quote=False)
        + "</pre></details>",
        "<footer>" + "".join(f"<p>{inline(c)}</p>" for c in credits) + "</footer></body></html>",
    ]
    return "\n".join(x for x in h if x)
