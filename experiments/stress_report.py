"""The stress report: where each method breaks down, as a heat map of failures by case and method, a reading in
numbers and ``stress.md`` with the whole table (``experiments.stress`` measures the cases).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from hybrid.atomic import write_parquet, write_text
from hybrid.terrain.datasets import PUGET_CREDIT


def failure_chart(df: pd.DataFrame, folder: Path) -> list[Path]:
    """Heat maps (scene/view x method) of hole fraction, depth error, capped rays and steps per ray."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = df.copy()
    d["case"] = d["scene"] + " / " + d["view"]
    px = d.get("hole_px", 0) + d.get("crack_px", 0)
    d["holes+cracks"] = px
    panels = [
        ("holes+cracks", "hole + crack pixels (log10(1+n))", lambda v: np.log10(1 + v)),
        ("depth_rel_p99", "p99 relative depth error (log10)", lambda v: np.log10(np.maximum(v, 1e-8))),
        ("capped", "capped rays", lambda v: np.log10(1 + v)),
        ("mean_steps", "mean steps per ray", lambda v: v),
    ]
    cases = list(dict.fromkeys(d["case"]))
    methods = list(dict.fromkeys(d["method"]))
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 0.22 * len(cases) + 2.5))
    for ax, (col, title, tf) in zip(axes, panels):
        grid = np.full((len(cases), len(methods)), np.nan)
        if col in d:
            piv = d.pivot_table(index="case", columns="method", values=col, aggfunc="max")
            for i, c in enumerate(cases):
                for j, m in enumerate(methods):
                    if c in piv.index and m in piv.columns:
                        grid[i, j] = tf(piv.loc[c, m])
        im = ax.imshow(grid, aspect="auto", cmap="magma", interpolation="nearest")
        ax.set_xticks(range(len(methods)), methods, rotation=60, ha="right", fontsize=7)
        ax.set_yticks(range(len(cases)), cases if ax is axes[0] else [""] * len(cases), fontsize=6)
        ax.set_title(title, fontsize=9)
        fig.colorbar(im, ax=ax, shrink=0.5)
    from .figures import save_figure

    return save_figure(fig, folder, "stress_failures")


def stress_reading(df: pd.DataFrame) -> list[str]:
    """Where each method breaks down, in numbers, and where the hybrid avoided it."""
    out = []
    ok = df[df["error"] == ""] if "error" in df else df
    for m, g in ok.groupby("method", sort=False):
        worst = g.sort_values("depth_rel_p99", ascending=False).iloc[0]
        holes = g[g["hole_px_strict"] > 0] if "hole_px_strict" in g else g[g["hole_px"] > 0]
        s = (
            f"{m}: worst p99 relative depth error {worst['depth_rel_p99']:.2g} on {worst['scene']}/{worst['view']}; "
            f"holes off the terrain's outline on {len(holes)} of {len(g)} cases"
        )
        if len(holes):
            h = holes.sort_values("hole_px_strict", ascending=False).iloc[0]
            s += f" (most: {int(h['hole_px_strict'])} px on {h['scene']}/{h['view']})"
        if g["rays"].sum() > 0:
            i = g["mean_steps"].idxmax()
            s += (
                f"; capped rays {int(g['capped'].sum())} of {int(g['rays'].sum())}; mean steps/ray up to "
                f"{g.loc[i, 'mean_steps']:.1f} ({g.loc[i, 'scene']}/{g.loc[i, 'view']})"
            )
        if g["nan_px"].sum():
            s += f"; NaN pixels {int(g['nan_px'].sum())}"
        out.append(s + ".")
    if {"hybrid", "raster"} <= set(ok["method"]):
        piv = ok.pivot_table(index=["scene", "view"], columns="method", values="depth_rel_p99")
        better = piv[piv["hybrid"] < 0.5 * piv["raster"]]
        if len(better):
            out.append(
                f"hybrid: on {len(better)} of {len(piv)} cases its p99 depth error is under half the raster "
                f"path's (it sent the failing tiles to the ray caster), e.g. "
                + ", ".join(
                    f"{sc}/{v} {r['hybrid']:.2g} vs {r['raster']:.2g}" for (sc, v), r in better.head(3).iterrows()
                )
                + "."
            )
    if "user_refused" in df and df["user_refused"].any():
        flagged = sorted({f"{r['scene']}/{r['view']}" for _, r in df[df["user_refused"]].iterrows()})
        out.append(
            f"{len(flagged)} cases put the eye under the ground or within the near plane of it "
            f"({', '.join(flagged[:6])}{', ...' if len(flagged) > 6 else ''}): `render` and runs refuse such "
            "views; here they show how each method fails, not a fair comparison with the reference."
        )
    if "error" in df:
        for _, r in df[df["error"] != ""].iterrows():
            out.append(f"{r['method']} failed on {r['scene']}/{r['view']}: {r['error']}.")
    for sc in ok["scene"].unique():
        g = ok[ok["scene"] == sc]
        a = g[g["view"] == "offset_1e7"].set_index("method")["depth_rel_p99"]
        b = g[g["view"] == "origin"].set_index("method")["depth_rel_p99"]
        if len(a) and len(b):
            ratio = (a / b.where(b > 0)).max()
            out.append(
                f"{sc}: the same view 10^7 m from the origin: worst p99 depth error {a.max():.2g} vs "
                f"{b.max():.2g} at the origin (largest per-method ratio {ratio:.2f})."
            )
    return out


def write_stress_report(df: pd.DataFrame, folder: Path) -> Path:
    """stress.md (+ table as parquet/csv and the chart) into folder."""
    from .tables import md_table

    folder.mkdir(parents=True, exist_ok=True)
    write_parquet(folder / "stress.parquet", df)
    write_text(folder / "stress.csv", df.to_csv(index=False))
    chart = failure_chart(df, folder)
    cols = [
        c
        for c in (
            "scene",
            "view",
            "method",
            "hole_px",
            "crack_px",
            "depth_rel_p99",
            "capped",
            "mean_steps",
            "max_steps",
            "triangles",
            "wall_ms",
            "nan_px",
        )
        if c in df
    ]
    md = (
        [
            "# Stability where methods fail",
            "",
            "Each row renders one stress case with one method and compares it to the full-resolution reference "
            "of the same view. *Holes* are pixels where the reference has terrain and the method has none; "
            "*cracks* are pixels without terrain with terrain above them in their image column.",
            "",
            "## Reading",
            "",
        ]
        + [f"- {s}" for s in stress_reading(df)]
        + ["", f"![failures]({chart[0].name})", "", "## All cases", "", md_table(df[cols]), ""]
    )
    if df["scene"].astype(str).str.startswith("puget").any():  # credit the bundled data when it was used
        md += ["---", f"- {PUGET_CREDIT}", ""]
    return write_text(folder / "stress.md", "\n".join(md))
