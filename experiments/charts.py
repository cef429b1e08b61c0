"""Charts of a run (matplotlib, PNG and SVG): frame time, memory, speed vs accuracy, strategy mix, popping, images."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402

STRATEGY_CMAP = ListedColormap(["#f2f2f2", "#2b6cff", "#ff8c14"])   # no terrain, raster, ray cast


def label_columns(frames: pd.DataFrame) -> pd.DataFrame:
    """Add 'method' (policy, plus tau / reconstruction where the run varies them) and 'scene' columns."""
    f = frames.copy()
    many_tau = f["tau"].nunique() > 1
    many_rec = f["reconstruction"].nunique() > 1
    def method(r):
        s = r["policy"]
        if many_rec and r["policy"] not in ("raster", "reference", "fullres", "tin"):
            s += f"/{r['reconstruction']}"
        if many_tau and r["policy"] != "reference":
            s += f" tau={r['tau']:.3g}"
        return s
    f["method"] = f.apply(method, axis=1)
    f["scene"] = f["dataset"].map(lambda d: Path(str(d)).stem) + " / " + f["flight"].map(lambda d: Path(str(d)).stem) \
        + " / " + f["size"]
    return f


def save_figure(fig, folder: Path, name: str) -> list[Path]:
    """Write a figure as folder/name.png and .svg, close it; returns both paths."""
    out = []
    for ext in ("png", "svg"):
        p = folder / f"{name}.{ext}"
        fig.savefig(p, dpi=110, bbox_inches="tight")
        out.append(p)
    plt.close(fig)
    return out


def _per_scene(f: pd.DataFrame, folder: Path, name: str, ycol: str, ylabel: str, scale=1.0) -> list[Path]:
    scenes = sorted(f["scene"].unique())
    fig, axes = plt.subplots(len(scenes), 1, figsize=(8, 3.2 * len(scenes)), squeeze=False)
    for ax, sc in zip(axes[:, 0], scenes):
        sub = f[f["scene"] == sc]
        for m, g in sub.groupby("method"):
            g = g.sort_values("frame")
            ax.plot(g["frame"], g[ycol] * scale, marker=".", label=m)
        ax.set_title(sc, fontsize=10)
        ax.set_xlabel("frame")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, ncol=3)
    return save_figure(fig, folder, name)


def frame_time_chart(f, folder) -> list[Path]:
    """Frame time over the flight per method (as Dick et al. Figs. 9/10)."""
    return _per_scene(f, folder, "frame_time", "wall_ms", "frame time (ms, wall clock)")


def memory_chart(f, folder) -> list[Path]:
    """Resident GPU memory over the flight per method."""
    return _per_scene(f, folder, "gpu_memory", "gpu_bytes", "GPU memory (MiB)", 1 / 2**20)


def depth_jump_chart(f, folder) -> list[Path]:
    """Popping over the flight per method: the largest change of a pixel's hit distance from the previous frame,
    against the reference's own (1 = no more than the camera's motion)."""
    if "depth_jump_ratio" not in f or not f["depth_jump_ratio"].notna().any():
        return []
    return _per_scene(f, folder, "depth_jump", "depth_jump_ratio", "largest depth jump / reference's")


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
    """Median frame time against mean image error per method and scene, Pareto front marked."""
    err_col = "flip" if "flip" in f and f["flip"].notna().any() else "ssim"
    agg = f.groupby(["scene", "method"]).agg(ms=("wall_ms", "median"), err=(err_col, "mean")).reset_index()
    if err_col == "ssim":
        agg["err"] = 1 - agg["err"]
    scenes = sorted(agg["scene"].unique())
    fig, axes = plt.subplots(1, len(scenes), figsize=(6 * len(scenes), 4.5), squeeze=False)
    for ax, sc in zip(axes[0], scenes):
        a = agg[agg["scene"] == sc].reset_index(drop=True)
        ax.scatter(a["ms"], a["err"], zorder=3)
        # methods that land on top of each other get their labels stacked instead of overprinted
        order = a.sort_values(["err", "ms"]).reset_index(drop=True)
        span_x = max(float(a["ms"].max() - a["ms"].min()), 1e-9)
        span_y = max(float(a["err"].max() - a["err"].min()), 1e-12)
        placed = []
        for _, r in order.iterrows():
            near = [k for (x, y, k) in placed if abs(x - r["ms"]) < 0.15 * span_x and abs(y - r["err"]) < 0.05 * span_y]
            k = max(near) + 1 if near else 0
            placed.append((r["ms"], r["err"], k))
            ax.annotate(r["method"], (r["ms"], r["err"]), fontsize=8, xytext=(4, 3 + 10 * k), textcoords="offset points")
        pts = a[["ms", "err"]].to_numpy()
        ok = np.all(np.isfinite(pts), axis=1)
        if ok.sum() >= 1:
            fr = pareto_front(pts[ok])
            p = pts[ok][fr]
            ax.step(p[:, 0], p[:, 1], where="post", color="C3", alpha=0.7, label="Pareto front")
            ax.scatter(p[:, 0], p[:, 1], s=90, facecolors="none", edgecolors="C3", zorder=4)
        ax.set_xlabel("median frame time (ms)")
        ax.set_ylabel("mean FLIP vs reference" if err_col == "flip" else "1 - SSIM vs reference")
        ax.set_title(sc, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    return save_figure(fig, folder, "speed_vs_accuracy")


def strategy_mix_chart(f, folder) -> list[Path]:
    """Tiles per strategy per frame for the mixed policies."""
    mixed = f[f["policy"].isin(["hybrid", "heuristic", "oracle"])]
    if mixed.empty or "tiles_raster" not in mixed:
        return []
    groups = list(mixed.groupby(["scene", "method"]))
    fig, axes = plt.subplots(len(groups), 1, figsize=(8, 2.6 * len(groups)), squeeze=False)
    for ax, ((sc, m), g) in zip(axes[:, 0], groups):
        g = g.sort_values("frame")
        ax.bar(g["frame"], g["tiles_raster"], label="raster", color="C0")
        ax.bar(g["frame"], g["tiles_raycast"], bottom=g["tiles_raster"], label="ray cast", color="C1")
        ax.set_title(f"{m} — {sc}", fontsize=10)
        ax.set_xlabel("frame")
        ax.set_ylabel("tiles")
        ax.legend(fontsize=8)
    return save_figure(fig, folder, "strategy_mix")


def crossover_chart(tiles: pd.DataFrame, folder: Path) -> list[Path]:
    """Per tile timed both ways (the oracle's measurements): ms per covered pixel of each strategy, and their
    ratio, against triangles per pixel; where the ratio crosses 1 rasterizing starts to pay on this device."""
    t = tiles.dropna(subset=["meas_raster_ms", "meas_raycast_ms"]) if len(tiles) else tiles
    if t.empty or "f_triangles" not in t:
        return []
    px = np.maximum(t["f_pixels"].to_numpy(float), 1.0)
    tpp = np.maximum(t["f_triangles"].to_numpy(float) / px, 1e-4)
    ras, ray = t["meas_raster_ms"].to_numpy(float), t["meas_raycast_ms"].to_numpy(float)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    axes[0].scatter(tpp, 1e3 * ras / px, s=8, alpha=0.5, label="raster (tile drawn alone)", color="C0")
    axes[0].scatter(tpp, 1e3 * ray / px, s=8, alpha=0.5, label="ray cast (tile drawn alone)", color="C1")
    axes[0].set_ylabel("µs per covered pixel")
    axes[1].scatter(tpp, ras / ray, s=8, alpha=0.5, color="C2")
    axes[1].axhline(1.0, color="k", lw=1)
    edges = np.quantile(tpp, np.linspace(0, 1, 9))
    mid = [np.median((ras / ray)[(tpp >= a) & (tpp <= b)]) for a, b in zip(edges[:-1], edges[1:])]
    axes[1].plot(np.sqrt(edges[:-1] * edges[1:]), mid, "o-", color="C3", label="median per bin")
    axes[1].set_ylabel("raster ms / ray-cast ms (below 1: raster is faster)")
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
                    extra = {m.name.split(".")[-2]: np.load(m) for m in img.glob(f"{r['config']}-f{k}.*.npy")
                             if not m.name.endswith(".depth.npy")}
                    panels.append((r["method"], np.asarray(Image.open(p)), extra))
            if not panels:
                continue
            ncol = 2 + max(len(e) for _, _, e in panels)
            fig, axes = plt.subplots(len(panels) + 1, ncol, figsize=(3.2 * ncol, 2.0 * (len(panels) + 1)), squeeze=False)
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
                    axes[i, j].set_title({"strategy": "strategy (blue raster, orange ray cast)"}.get(name, name), fontsize=8)
            fig.colorbar(h, ax=axes[1:, 1].tolist(), shrink=0.6)
            safe = scene.replace(" / ", "_").replace(" ", "")
            out += save_figure(fig, folder, f"images_{safe}_f{k}")
    return out


def all_charts(run: Path, frames: pd.DataFrame, folder: Path, image_frames: list[int],
               tiles: pd.DataFrame | None = None) -> dict[str, list[Path]]:
    """Every chart of a run into folder; returns name -> files."""
    folder.mkdir(parents=True, exist_ok=True)
    f = label_columns(frames)
    return {"frame_time": frame_time_chart(f, folder), "gpu_memory": memory_chart(f, folder),
            "speed_vs_accuracy": speed_accuracy_chart(f, folder), "strategy_mix": strategy_mix_chart(f, folder),
            "depth_jump": depth_jump_chart(f, folder),
            "crossover": crossover_chart(tiles if tiles is not None else pd.DataFrame(), folder),
            "images": image_panels(run, f, folder, image_frames)}
