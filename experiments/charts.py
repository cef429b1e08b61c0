"""Charts of a run (matplotlib, PNG and SVG): frame time, memory, speed vs accuracy, strategy mix, popping, images.

Charts with one panel per scene or method lay their panels out in rows of up to MAX_COLS (``panel_grid``, in
``experiments.figures``) with one legend for the whole figure, so they stay readable from 1 to 20 panels."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import itertools

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.colors import ListedColormap
from matplotlib.ticker import MaxNLocator

from hybrid.contract import PRIOR_FULL_RES
from hybrid.strategies import mixed_policies, policies_taking

from .figures import figure_legend, grid_cols, method_colours, panel_grid, panel_title, save_figure
from .noise import median_interval, repeat_matrix

STRATEGY_CMAP = ListedColormap(["#f2f2f2", "#2b6cff", "#ff8c14"])  # no terrain, raster, ray cast
DEVICE_START = "device"  # the hybrid's default starting cost model; others are named in its label (from-<start>)


def label_columns(frames: pd.DataFrame) -> pd.DataFrame:
    """Add 'method' (policy, plus tau / reconstruction / full-resolution rule where the run varies them, and a
    hybrid's starting cost model where it is not the device's; 'full_res' ``PRIOR_FULL_RES`` where a run's rows
    lack it) and 'scene' columns; a run timed on several devices (a cluster) gets the
    device in its scene, so no chart or sentence compares frame times across devices."""
    f = frames.copy()
    f["full_res"] = f["full_res"].fillna(PRIOR_FULL_RES) if "full_res" in f else PRIOR_FULL_RES
    many_tau = f["tau"].nunique() > 1
    many_rec = f["reconstruction"].nunique() > 1
    tilelets = policies_taking("full_res")
    many_fr = f.loc[f["policy"].isin(tilelets), "full_res"].nunique() > 1  # others record the prior rule

    def method(r):
        s = r["policy"]
        if many_rec and r["policy"] not in ("raster", "reference", "fullres", "tin"):
            s += f"/{r['reconstruction']}"
        if many_fr and r["policy"] in tilelets:
            s += f"/{r['full_res']}"
        start = r.get("start_model")
        if r["policy"] == "hybrid" and isinstance(start, str) and start != DEVICE_START:
            s += f"/from-{start}"
        if many_tau and r["policy"] != "reference":
            s += f" tau={r['tau']:.3g}"
        return s

    f["method"] = f.apply(method, axis=1)
    f["scene"] = (
        f["dataset"].map(lambda d: Path(str(d)).stem)
        + " / "
        + f["flight"].map(lambda d: Path(str(d)).stem)
        + " / "
        + f["size"]
    )
    if "device" in f and f["device"].nunique() > 1:
        f["scene"] = f["scene"] + " / " + f["device"].fillna("unknown device").astype(str)
    return f


def _per_scene(
    f: pd.DataFrame,
    folder: Path,
    name: str,
    ycol: str,
    ylabel: str,
    scale=1.0,
    band=None,
    counts: bool = False,
    dashed: str | None = None,
) -> list[Path]:
    """One panel per scene of ``ycol`` over the frames, a line per method (``dashed``: a second column, drawn
    dashed in the method's colour)."""
    scenes = sorted(f["scene"].unique())
    fig, axes = panel_grid(len(scenes))
    colours = method_colours(f)
    cols = grid_cols(len(scenes))
    for ax, sc in zip(axes, scenes):
        sub = f[f["scene"] == sc]
        for m, g in sub.groupby("method"):
            g = g.sort_values("frame")
            ax.plot(g["frame"], g[ycol] * scale, marker=".", label=m, color=colours[m])
            if dashed and dashed in g and g[dashed].notna().any():
                ax.plot(g["frame"], g[dashed] * scale, ls="--", lw=1, color=colours[m])
            if band and all(c in g and g[c].notna().all() for c in band):
                ax.fill_between(g["frame"], g[band[0]] * scale, g[band[1]] * scale, color=colours[m], alpha=0.15, lw=0)
        panel_title(ax, sc, cols)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        if counts:  # pixel counts: whole numbers from 0
            ax.yaxis.set_major_locator(MaxNLocator(integer=True))
            ax.set_ylim(0, max(1.0, ax.get_ylim()[1]))
        ax.set_xlabel("frame")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    figure_legend(fig, axes)
    return save_figure(fig, folder, name)


def frame_time_chart(f, folder) -> list[Path]:
    """Frame time over the flight per method (as Dick et al. Figs. 9/10): median of repeats, shaded min to max."""
    return _per_scene(
        f, folder, "frame_time", "wall_ms", "frame time (ms, wall clock)", band=("wall_ms_min", "wall_ms_max")
    )


def memory_chart(f, folder) -> list[Path]:
    """Resident GPU memory over the flight per method."""
    return _per_scene(f, folder, "gpu_memory", "gpu_bytes", "GPU memory (MiB)", 1 / 2**20)


def popping_chart(f, folder) -> list[Path]:
    """Popping over the flight per method: pixels whose depth error steps in one frame, and (dashed) as many with
    the frame's level of detail held (experiments.popping)."""
    if "pop_px" not in f or not f["pop_px"].notna().any():
        return []
    measured = f.groupby("scene")["pop_px"].transform(lambda s: s.notna().any())  # slow flights only
    return _per_scene(
        f[measured],
        folder,
        "popping",
        "pop_px",
        "pixels popping around the frame\n(dashed: level of detail held)",
        counts=True,
        dashed="pop_static_px",
    )


def pareto_front(points: np.ndarray) -> np.ndarray:
    """Indices of the points not dominated in (time, error), both smaller-is-better, sorted by time."""
    order = np.lexsort((points[:, 1], points[:, 0]))
    front, best = [], np.inf
    for i in order:
        if points[i, 1] < best:
            front.append(i)
            best = points[i, 1]
    return np.array(front, dtype=int)


def speed_accuracy_chart(f, folder) -> list[Path]:
    """Median frame time (bar: its 95 % bootstrap interval over frames and repeats) against mean image error over
    terrain pixels, per method (one colour each) and scene; Pareto front marked."""
    err_col = "flip" if "flip" in f and f["flip"].notna().any() else "ssim"
    if err_col not in f:  # a run without accuracy (spec accuracy = false)
        return []
    rows = []
    for (sc, m), g in f.groupby(["scene", "method"]):
        lo, hi = median_interval(repeat_matrix(g))
        err = float(g[err_col].mean())
        rows.append(
            {
                "scene": sc,
                "method": m,
                "ms": float(g["wall_ms"].median()),
                "lo": lo,
                "hi": hi,
                "err": 1 - err if err_col == "ssim" else err,
            }
        )
    agg = pd.DataFrame(rows)
    scenes = sorted(agg["scene"].unique())
    fig, axes = panel_grid(len(scenes), width=5.0, height=3.8, wide=7.5)
    colours = method_colours(agg)
    for ax, sc in zip(axes, scenes):
        a = agg[agg["scene"] == sc].reset_index(drop=True)
        for _, r in a.iterrows():  # one colour per method, named in the figure's legend
            ax.errorbar(
                [r["ms"]],
                [r["err"]],
                xerr=[[r["ms"] - r["lo"]], [r["hi"] - r["ms"]]],
                fmt="o",
                ms=5,
                capsize=2,
                color=colours[r["method"]],
                label=r["method"],
                zorder=3,
            )
        pts = a[["ms", "err"]].to_numpy()
        ok = np.all(np.isfinite(pts), axis=1)
        if ok.sum() >= 1:
            fr = pareto_front(pts[ok])
            p = pts[ok][fr]
            ax.step(p[:, 0], p[:, 1], where="post", color="C3", alpha=0.7, label="Pareto front")
            ax.scatter(p[:, 0], p[:, 1], s=90, facecolors="none", edgecolors="C3", zorder=4)
        ax.set_xlabel("median frame time (ms; bars: 95 % interval)")
        ax.set_ylabel("mean FLIP over terrain" if err_col == "flip" else "1 - SSIM over terrain")
        panel_title(ax, sc, grid_cols(len(scenes)))
        ax.grid(alpha=0.3)
    figure_legend(fig, axes)
    return save_figure(fig, folder, "speed_vs_accuracy")


def strategy_mix_chart(f, folder) -> list[Path]:
    """Tiles per strategy per frame for the mixed policies, one panel per method and scene."""
    mixed = f[f["policy"].isin(mixed_policies())]
    if mixed.empty or "tiles_raster" not in mixed:
        return []
    groups = list(mixed.groupby(["scene", "method"]))
    fig, axes = panel_grid(len(groups), width=4.2, height=2.6, wide=8.0)
    for ax, ((sc, m), g) in zip(axes, groups):
        g = g.sort_values("frame")
        gs = g["tiles_gs"].fillna(0) if "tiles_gs" in g else 0 * g["tiles_raster"]
        ax.bar(g["frame"], g["tiles_raster"] - gs, label="raster", color="C0")
        ax.bar(g["frame"], gs, bottom=g["tiles_raster"] - gs, label="raster_gs", color="C2")
        ax.bar(g["frame"], g["tiles_raycast"], bottom=g["tiles_raster"], label="ray cast", color="C1")
        panel_title(ax, f"{m}\n{sc}", grid_cols(len(groups)))
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("frame")
        ax.set_ylabel("tiles")
    figure_legend(fig, axes)
    return save_figure(fig, folder, "strategy_mix")


def crossover_chart(tiles: pd.DataFrame, folder: Path) -> list[Path]:
    """Per tile timed every candidate way inside frames (the oracle's measurements): ms per covered pixel of each
    strategy, and the faster raster strategy's time over the ray caster's, against triangles per pixel; where
    the ratio crosses 1 rasterizing starts to pay on this device."""
    raster = [s for s in ("raster", "raster_gs") if f"meas_{s}_ms" in tiles]
    t = (
        tiles.dropna(subset=[f"meas_{s}_ms" for s in (*raster, "raycast")])
        if len(tiles) and raster and "meas_raycast_ms" in tiles
        else tiles.iloc[:0]
    )
    if t.empty or "f_triangles" not in t:
        return []
    px = np.maximum(t["f_pixels"].to_numpy(float), 1.0)
    tpp = np.maximum(t["f_triangles"].to_numpy(float) / px, 1e-4)
    ms = {s: t[f"meas_{s}_ms"].to_numpy(float) for s in (*raster, "raycast")}
    ras = np.min([ms[s] for s in raster], axis=0)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), layout="constrained")
    for s, colour in zip(ms, ("C0", "C2", "C1")):
        c = "C1" if s == "raycast" else colour
        axes[0].scatter(tpp, 1e3 * ms[s] / px, s=8, alpha=0.5, label=f"{s} (tile timed inside its frame)", color=c)
    axes[0].set_ylabel("µs per covered pixel")
    ratio = ras / ms["raycast"]
    axes[1].scatter(tpp, ratio, s=8, alpha=0.5, color="C3")
    axes[1].axhline(1.0, color="k", lw=1)
    edges = np.quantile(tpp, np.linspace(0, 1, 9))
    mid = [np.median(ratio[(tpp >= a) & (tpp <= b)]) for a, b in itertools.pairwise(edges)]
    axes[1].plot(np.sqrt(edges[:-1] * edges[1:]), mid, "o-", color="C4", label="median per bin")
    axes[1].set_ylabel("faster raster ms / ray-cast ms (below 1: raster pays)")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("raster triangles per covered pixel (cost-model estimate / box footprint)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.suptitle(f"where each strategy pays, {len(t)} tiles", fontsize=10)
    return save_figure(fig, folder, "crossover")


def image_panels(run: Path, f: pd.DataFrame, folder: Path, frames: list[int]) -> list[Path]:
    """For chosen frames: each method's image, its error heat map against the reference, and its maps."""
    from PIL import Image

    out = []
    img = run / "images"
    for scene, sf in f.groupby("scene"):
        for k in frames:
            rows = sf[sf["frame"] == k].drop_duplicates("config")
            if rows.empty:
                continue
            r0 = rows.iloc[0]
            gid = f"{Path(str(r0['dataset'])).stem}-s{r0['seed']}-{Path(str(r0['flight'])).stem}-{r0['size']}"
            ref_png = img / f"ref-{gid}-f{k}.png"
            if not ref_png.exists():
                continue
            ref = np.asarray(Image.open(ref_png)).astype(float)
            panels = []
            for _, r in rows.iterrows():
                p = img / f"{r['config']}-f{k}.png"
                if p.exists():
                    extra = {
                        m.name.split(".")[-2]: np.load(m)
                        for m in img.glob(f"{r['config']}-f{k}.*.npy")
                        if not m.name.endswith(".depth.npy")
                    }
                    panels.append((r["method"], np.asarray(Image.open(p)), extra))
            if not panels:
                continue
            ncol = 2 + max(len(e) for _, _, e in panels)
            fig, axes = plt.subplots(
                len(panels) + 1, ncol, figsize=(3.2 * ncol, 2.0 * (len(panels) + 1)), squeeze=False
            )
            for ax in axes.ravel():
                ax.axis("off")
            axes[0, 0].imshow(ref.astype(np.uint8))
            axes[0, 0].set_title("reference", fontsize=8)
            for i, (m, im, extra) in enumerate(panels, start=1):
                axes[i, 0].imshow(im)
                axes[i, 0].set_title(m, fontsize=8)
                err = np.abs(im.astype(float) - ref).mean(axis=2)
                h = axes[i, 1].imshow(err, cmap="magma", vmin=0, vmax=64)
                axes[i, 1].set_title("|error| (8-bit)", fontsize=8)
                for j, (name, arr) in enumerate(sorted(extra.items()), start=2):
                    if name == "strategy":
                        axes[i, j].imshow(arr, cmap=STRATEGY_CMAP, vmin=0, vmax=2, interpolation="nearest")
                    else:
                        axes[i, j].imshow(arr, cmap="inferno", interpolation="nearest")
                    axes[i, j].set_title(
                        {"strategy": "strategy (blue raster, orange ray cast)"}.get(name, name), fontsize=8
                    )
            fig.colorbar(h, ax=axes[1:, 1].tolist(), shrink=0.6)
            safe = scene.replace(" / ", "_").replace(" ", "")
            out += save_figure(fig, folder, f"images_{safe}_f{k}")
    return out


def all_charts(
    run: Path, frames: pd.DataFrame, folder: Path, image_frames: list[int], tiles: pd.DataFrame | None = None
) -> dict[str, list[Path]]:
    """Every chart of a run into folder; returns name -> files."""
    folder.mkdir(parents=True, exist_ok=True)
    f = label_columns(frames)
    return {
        "frame_time": frame_time_chart(f, folder),
        "gpu_memory": memory_chart(f, folder),
        "speed_vs_accuracy": speed_accuracy_chart(f, folder),
        "strategy_mix": strategy_mix_chart(f, folder),
        "popping": popping_chart(f, folder),
        "crossover": crossover_chart(tiles if tiles is not None else pd.DataFrame(), folder),
        "images": image_panels(run, f, folder, image_frames),
    }
