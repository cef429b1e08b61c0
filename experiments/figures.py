"""Figure plumbing shared by the chart modules: panel grids of up to MAX_COLS columns, wrapped panel titles, one
legend for the whole figure, one colour per method, and figures saved as PNG and SVG whole or not at all."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd

from hybrid.atomic import atomic_path

MAX_COLS = 4  # panels a row


def save_figure(fig, folder: Path, name: str) -> list[Path]:
    """Write a figure as folder/name.png and .svg, close it; returns both paths."""
    out = []
    for ext in ("png", "svg"):
        p = folder / f"{name}.{ext}"
        with atomic_path(p) as tmp:
            fig.savefig(tmp, dpi=110, bbox_inches="tight", format=ext)
        out.append(p)
    plt.close(fig)
    return out


def grid_cols(n: int) -> int:
    """Columns for n panels: one up to two panels, else about a square, at most MAX_COLS."""
    return 1 if n <= 2 else min(MAX_COLS, math.ceil(math.sqrt(n)))


def panel_grid(n: int, width: float = 4.6, height: float = 3.0, wide: float = 8.0):
    """A figure of n panels in grid_cols(n) columns, panels width x height inches (wide when one column);
    returns (figure, the n axes). Constrained layout keeps titles, labels and the figure legend apart."""
    cols = grid_cols(n)
    rows = math.ceil(n / cols)
    w = wide if cols == 1 else width
    fig, axes = plt.subplots(rows, cols, figsize=(w * cols, height * rows), squeeze=False, layout="constrained")
    flat = list(axes.ravel())
    for ax in flat[n:]:
        ax.set_visible(False)
    return fig, flat[:n]


def panel_title(ax, text: str, cols: int) -> None:
    """A panel title, each of its lines wrapped to the panel's width (small font)."""
    width = 90 if cols == 1 else 44
    ax.set_title("\n".join(w for line in text.split("\n") for w in textwrap.wrap(line, width)), fontsize=9)


def figure_legend(fig, axes) -> None:
    """One legend above all panels, with every label any panel drew (each once)."""
    seen: dict = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(lab, h)
    if seen:
        fig.legend(
            list(seen.values()),
            list(seen),
            loc="outside upper center",
            fontsize=8,
            ncol=min(len(seen), 4),
            frameon=False,
        )


def method_colours(f: pd.DataFrame) -> dict:
    """One colour per method, the same in every panel."""
    cmap = plt.get_cmap("tab20" if f["method"].nunique() > 10 else "tab10")
    return {m: cmap(i % cmap.N) for i, m in enumerate(sorted(f["method"].unique()))}
