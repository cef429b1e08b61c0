"""Charts of an edit run: update cost against brush radius per method, frame time with editing on against off, and
the images of the last image frame (reference and methods, static and at the largest radius)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.ticker import NullFormatter

from .charts import save_figure

STEPS = ("brush", "pyramid", "raster_nodes", "raster", "raster_gs", "raycast", "estimate")
"""The TerrainEditor's timed steps (``hybrid.editing.EditReport.ms``), in the order it runs them."""


def per_edit(f: pd.DataFrame) -> pd.DataFrame:
    """The edited frames' update ms per edit (``update_ms`` / ``edits``) and per step, with the frame's total cost
    (``total_ms``: draw plus update, milliseconds)."""
    e = f[f["editing"] & (f["edits"] > 0)].copy()
    e["update_per_edit_ms"] = e["update_ms"] / e["edits"]
    for s in STEPS:
        col = f"update_{s}_ms"
        e[f"{s}_per_edit_ms"] = e.get(col, np.nan) / e["edits"]
    return e


def update_chart(f: pd.DataFrame, folder: Path) -> list[Path]:
    """Median update ms per edit against brush radius (m), a line per method, beside the GPU brush pass alone."""
    e = per_edit(f)
    if e.empty:
        return []
    fig, ax = plt.subplots(figsize=(8.6, 4.0), layout="constrained")
    cmap = plt.get_cmap("tab10")
    for i, (policy, g) in enumerate(e.groupby("policy", sort=True)):
        m = g.groupby("edit_radius")["update_per_edit_ms"].median()
        ax.plot(m.index, m.values, "o-", color=cmap(i), label=f"{policy}: every step")
    brush = e.groupby("edit_radius")["brush_per_edit_ms"].median()
    ax.plot(brush.index, brush.values, "s--", color="0.45", label="brush pass alone (GPU, every method)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(sorted(e["edit_radius"].unique()), [f"{r:g}" for r in sorted(e["edit_radius"].unique())])
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("brush radius (m)")
    ax.set_ylabel("update ms per edit (median over frames)")
    ax.set_title("What each method pays to follow one edit", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    fig.legend(fontsize=8, loc="outside right upper", frameon=False)
    return save_figure(fig, folder, "update_vs_radius")


def on_off_chart(f: pd.DataFrame, folder: Path) -> list[Path]:
    """Per method, median frame ms on the static terrain beside each radius's median frame ms and update ms
    (stacked): frame time with editing off against on."""
    policies = sorted(f["policy"].unique())
    variants = [0.0] + sorted(r for r in f["edit_radius"].unique() if r > 0)
    fig, ax = plt.subplots(figsize=(max(6.4, 1.6 * len(policies) * len(variants) / 2), 4.0), layout="constrained")
    width = 0.8 / len(variants)
    cmap = plt.get_cmap("viridis")
    for v, radius in enumerate(variants):
        draw, update = [], []
        for p in policies:
            g = f[(f["policy"] == p) & (f["edit_radius"] == radius)]
            draw.append(float(g["wall_ms"].median()) if len(g) else np.nan)
            update.append(float(g["update_ms"].median()) if len(g) else np.nan)
        x = np.arange(len(policies)) + (v - (len(variants) - 1) / 2) * width
        colour = "0.6" if radius == 0 else cmap(v / max(len(variants) - 1, 1) * 0.85)
        label = "editing off (static)" if radius == 0 else f"r = {radius:g} m"
        ax.bar(x, draw, width, color=colour, label=f"{label}: frame")
        if radius > 0:
            ax.bar(
                x,
                update,
                width,
                bottom=draw,
                color=colour,
                alpha=0.45,
                hatch="//",
                edgecolor="white",
                label=f"{label}: + update",
            )
    ax.set_xticks(np.arange(len(policies)), policies)
    ax.set_ylabel("ms a frame (median over frames)")
    ax.set_title("Frame time with editing off and on (one edit a frame, update stacked on the draw)", fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    return save_figure(fig, folder, "frame_on_off")


def images_chart(run: Path, f: pd.DataFrame, folder: Path, frame: int) -> list[Path]:
    """The reference and every method at ``frame``, on the static terrain and at the largest radius (particles
    drawn into the methods' frames), as one figure."""
    from PIL import Image

    radii = sorted(r for r in f["edit_radius"].unique() if r > 0)
    variants = [0.0] + radii[-1:]
    policies = sorted(f["policy"].unique())
    row0 = f.iloc[0]
    stem = (
        f"{Path(str(row0['dataset'])).stem}-s{row0['seed']}-{Path(str(row0['flight'])).stem}-{row0['size']}-"
        f"tau{float(row0['tau']):.4g}"
    )
    fig, axes = plt.subplots(
        len(variants),
        len(policies) + 1,
        figsize=(2.6 * (len(policies) + 1), 1.7 * len(variants)),
        squeeze=False,
        layout="constrained",
    )
    shown = 0
    for i, radius in enumerate(variants):
        tag = f"r{radius:g}m" if radius > 0 else "static"
        for j, name in enumerate(["reference", *policies]):
            ax = axes[i][j]
            ax.axis("off")
            path = run / "images" / (f"ref-{tag}-f{frame}.png" if j == 0 else f"{stem}-{name}-{tag}-f{frame}.png")
            if path.exists():
                ax.imshow(np.asarray(Image.open(path)))
                shown += 1
            ax.set_title(f"{name}, {tag}", fontsize=8)
    if not shown:
        plt.close(fig)
        return []
    fig.suptitle(f"Frame {frame}: the reference of the same heights, and each method with its particles", fontsize=9)
    return save_figure(fig, folder, "images")
