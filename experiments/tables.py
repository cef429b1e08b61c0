"""Named benchmark tables (title -> DataFrame) as plain text for the terminal and as markdown for files."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd


def md_table(df: pd.DataFrame, floatfmt: str = ".3g") -> str:
    """A pandas frame as a GitHub markdown table (a '|' inside a header or cell escaped, so columns stay put)."""

    def text(v) -> str:
        return str(v).replace("|", "\\|")

    def fmt(v):
        if isinstance(v, (float, np.floating)):
            return "–" if not math.isfinite(v) else format(float(v), floatfmt)
        return text(v)

    cols = list(df.columns)
    lines = ["| " + " | ".join(map(text, cols)) + " |", "|" + "---|" * len(cols)]
    for _, r in df.iterrows():
        lines.append("| " + " | ".join(fmt(r[c]) for c in cols) + " |")
    return "\n".join(lines)


def format_number(v) -> str:
    """A cell as text: floats to three significant digits without exponents from 1e-3 up, the rest as str."""
    if not isinstance(v, (float, np.floating)):
        return str(v)
    v = float(v)
    if not math.isfinite(v) or v == 0.0:
        return "–" if math.isnan(v) else format(v, "g")
    if abs(v) < 1e-3:
        return format(v, ".3g")
    return format(v, f".{max(0, 2 - math.floor(math.log10(abs(v))))}f")


def _cells(df: pd.DataFrame) -> pd.DataFrame:
    return df.map(format_number) if len(df) else df


def text_tables(tables: dict[str, pd.DataFrame]) -> str:
    """Every table under its title, aligned for a terminal."""
    return "\n\n".join(f"{title}\n{_cells(df).to_string(index=False)}" for title, df in tables.items())


def markdown_tables(tables: dict[str, pd.DataFrame], level: int = 3) -> str:
    """Every table under a markdown heading of the given level."""
    return "\n\n".join(f"{'#' * level} {title}\n\n{md_table(_cells(df))}" for title, df in tables.items())
