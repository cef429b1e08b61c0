"""Charts of how the hybrid's cost model settles and where a frame's time goes: convergence and GPU against CPU.

The convergence chart shows, per scene and tau, every hybrid's frame time over the flight (one line per starting
model: the device's own, the uncalibrated fallback) beside the pure methods and the oracle, and below it each
hybrid's prediction error per frame: ``|pred_ms - draw_ms| / draw_ms``, the model's predicted drawing time of
the tiles as it chose them against the drawing measured. The GPU-against-CPU chart needs the GL timer query
(``gpu_ms``), which llvmpipe lacks; where no frame has it, there is no chart and ``gpu_cpu_sentence`` says why.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from hybrid.strategies import candidates

from .figures import figure_legend, grid_cols, method_colours, panel_grid, panel_title, save_figure

NO_GPU_TIME = (
    "GPU and CPU time are not told apart: this GL has no valid timer query (a software rasterizer "
    "draws on the CPU), so frame time is the wall clock alone."
)


def prediction_error(rows: pd.DataFrame) -> pd.Series:
    """Per row, the hybrid's prediction error in %: ``|pred_ms - draw_ms| / draw_ms``."""
    return 100 * (rows["pred_ms"] - rows["draw_ms"]).abs() / rows["draw_ms"]


def _convergence_groups(f: pd.DataFrame) -> list[tuple[str, pd.DataFrame]]:
    """(panel title, rows) per scene and tau that has a hybrid with predictions, with that tau's pure methods
    and oracle."""
    out = []
    for (sc, tau), g in f[f["policy"] != "reference"].groupby(["scene", "tau"]):
        hy = g[g["policy"] == "hybrid"]
        if hy.empty or "pred_ms" not in hy or not hy["pred_ms"].notna().any():
            continue
        keep = g["policy"].isin((*candidates(), "hybrid", "oracle"))
        out.append((f"{sc}, tau {tau:.3g} px", g[keep]))
    return out


def convergence_chart(f: pd.DataFrame, folder: Path) -> list[Path]:
    """Per scene and tau: frame ms over the flight of each hybrid (solid, thick) against the pure methods and the
    oracle (thin), and below each hybrid's prediction error per frame (%); [] where no hybrid predicted."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    groups = _convergence_groups(f)
    if not groups:
        return []
    cols = grid_cols(len(groups))
    rows = -(-len(groups) // cols)
    fig, axes = plt.subplots(
        2 * rows,
        cols,
        figsize=(4.8 * cols if cols > 1 else 8.0, 5.2 * rows),
        squeeze=False,
        layout="constrained",
        gridspec_kw={"height_ratios": [3, 1.4] * rows},
    )
    colours = method_colours(pd.concat([g for _, g in groups]))
    used = []
    for i, (title, g) in enumerate(groups):
        top, bottom = axes[2 * (i // cols), i % cols], axes[2 * (i // cols) + 1, i % cols]
        used += [top, bottom]
        for m, mg in g.groupby("method"):
            mg = mg.sort_values("frame")
            hybrid = mg["policy"].iloc[0] == "hybrid"
            top.plot(
                mg["frame"],
                mg["wall_ms"],
                marker="." if hybrid else None,
                lw=2.2 if hybrid else 1.0,
                alpha=1.0 if hybrid else 0.8,
                color=colours[m],
                label=m,
            )
            if hybrid:
                bottom.plot(mg["frame"], prediction_error(mg), marker=".", color=colours[m], label=m)
        panel_title(top, title, cols)
        top.set_ylabel("frame time (ms)")
        bottom.set_ylabel("prediction\nerror (%)")
        bottom.set_xlabel("frame")
        bottom.set_ylim(bottom=0)
        for ax in (top, bottom):
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            ax.grid(alpha=0.3)
    for ax in axes.ravel():
        if not any(ax is u for u in used):
            ax.set_visible(False)
    figure_legend(fig, used)
    return save_figure(fig, folder, "convergence")


def _timed_both(f: pd.DataFrame) -> pd.DataFrame:
    """The frames of the methods (the reference left out) that carry both a GL timer query time and a CPU time."""
    if "gpu_ms" not in f or "cpu_ms" not in f:
        return f.iloc[:0]
    return f[f["gpu_ms"].notna() & f["cpu_ms"].notna() & (f["policy"] != "reference")]


def has_gpu_time(f: pd.DataFrame) -> bool:
    """Whether any method's frame carries both a GL timer query time and a CPU time."""
    return not _timed_both(f).empty


def gpu_cpu_chart(f: pd.DataFrame, folder: Path) -> list[Path]:
    """Per scene, every frame's GPU ms (timer query) against its CPU ms (planning, issue, learning), a colour per
    method, with the diagonal: frames above it are bound by the GPU; [] where no frame has both times."""
    g = _timed_both(f)
    if g.empty:
        return []
    scenes = sorted(g["scene"].unique())
    fig, axes = panel_grid(len(scenes), width=4.6, height=4.2, wide=6.5)
    colours = method_colours(g)
    for ax, sc in zip(axes, scenes):
        s = g[g["scene"] == sc]
        for m, mg in s.groupby("method"):
            ax.scatter(mg["cpu_ms"], mg["gpu_ms"], s=14, alpha=0.7, color=colours[m], label=m)
        hi = float(np.nanmax(s[["cpu_ms", "gpu_ms"]].to_numpy())) * 1.05
        ax.plot([0, hi], [0, hi], color="k", lw=0.8, label="GPU = CPU")
        ax.set_xlim(0, hi)
        ax.set_ylim(0, hi)
        ax.set_xlabel("CPU ms (plan + issue + learning)")
        ax.set_ylabel("GPU ms (timer query)")
        panel_title(ax, sc, grid_cols(len(scenes)))
        ax.grid(alpha=0.3)
    figure_legend(fig, axes)
    return save_figure(fig, folder, "gpu_vs_cpu")


def gpu_cpu_sentence(f: pd.DataFrame) -> str:
    """Per method, the share of frames the GPU bounds (GPU ms over CPU ms), or why GPU and CPU are not told apart."""
    g = _timed_both(f)
    if g.empty:
        return NO_GPU_TIME
    share = (g["gpu_ms"] > g["cpu_ms"]).groupby(g["method"]).mean().sort_values(ascending=False)
    return (
        "Frames bound by the GPU (timer query over CPU time): "
        + ", ".join(f"{m} {100 * v:.0f} %" for m, v in share.items())
        + "."
    )


def adaptation_sentences(f: pd.DataFrame, settled_from: int = 4) -> list[str]:
    """Per scene and tau where hybrids started from several models: each start's median frame ms from frame
    ``settled_from`` on against the device's start, and its median prediction error first and last."""
    from .noise import compare

    out = []
    for title, g in _convergence_groups(f):
        hy = {m: q for m, q in g[g["policy"] == "hybrid"].groupby("method")}
        if len(hy) < 2:
            continue
        device = (
            [m for m, q in hy.items() if q["start_model"].fillna("device").eq("device").all()]
            if "start_model" in g
            else []
        )
        base = device[0] if device else None
        parts = []
        for m, q in hy.items():
            err = prediction_error(q).groupby(q["frame"]).median()
            s = (
                f"{m}: prediction error {err.iloc[0]:.0f} % at frame {int(err.index[0])}, "
                f"{err.iloc[-1]:.0f} % at frame {int(err.index[-1])}"
            )
            if base is not None and m != base:
                late = q["frame"] >= settled_from
                b = hy[base]
                c = compare(m, q[late], base, b[b["frame"] >= settled_from])
                s += f"; frames {settled_from}- {c.ms_a:.1f} ms against {c.ms_b:.1f} ms, {c.words()}"
            parts.append(s)
        out.append(f"Adaptation ({title}): " + "; ".join(parts) + ".")
    return out
