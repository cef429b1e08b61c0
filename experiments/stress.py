"""`terrabench stress`: scenes and views made to break methods, every method measured where it fails.

Scenes: spike, cliff, staircase, ridges, flat, Puget (a full-resolution window) and Puget with x100 vertical
exaggeration. Views: grazing (eye 2 m above ground at the horizon), straight down, eye inside a tile's AABB,
eye below the surface, view directions exactly along the x and y axes, the terrain 10^6 and 10^7 m from
the origin (with the same view at the origin as their baseline), and a tiny near / huge far plane. For every method and reconstruction: capped rays, NaN pixels,
hole pixels against the reference coverage, depth error, steps per ray, triangles and frame time.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from hybrid.atomic import remove_stale_temps, write_json, write_parquet
from hybrid.camera.view import View
from hybrid.errors import TerrabenchError
from hybrid.terrain.datasets import get_dataset, puget
from hybrid.terrain.heightfield import HeightField

SCENES = ("spike", "cliff", "staircase", "ridges", "flat", "puget", "puget_x100")
VIEWS = (
    "grazing",
    "down",
    "inside_aabb",
    "below",
    "axis_x",
    "axis_y",
    "origin",
    "offset_1e6",
    "offset_1e7",
    "near_far",
)
METHODS = (
    "raster",
    "raster_gs",
    "raster/exact",
    "raycast/planes",
    "raycast/linear",
    "raycast/triangles",
    "raycast/bilinear",
    "hybrid",
    "fullres",
    "tin",
)


def make_scene(name: str, size: int = 257) -> HeightField:
    """A stress scene by name, size x size samples."""
    if name == "puget":
        return puget(size=size)
    if name == "puget_x100":
        p = puget(size=size)
        assert p.source_step is not None  # puget is read from a 16-bit file
        step = p.source_step[0] * 100.0  # the 16-bit source at 10 m a unit, as a loader would make it
        h = (np.rint(p.heights / p.source_step[0]) * step).astype(np.float32)
        return HeightField(h, (p.spacing_x, p.spacing_y), p.origin, "puget_x100", p.texture, source_step=(step, 0.0))
    if name in SCENES:
        return get_dataset(name, size=size)
    raise TerrabenchError(f"unknown stress scene {name!r}; choose from {', '.join(SCENES)}")


def _oblique(hf: HeightField, width, height, near=None, far=None) -> View:
    w, d = hf.extent
    ox, oy, oz = hf.origin
    lo, hi = hf.height_range
    size = max(w, d)
    eye = np.array([ox + 0.2 * w, oy + 0.1 * d, oz + hi + 0.15 * size + 0.05 * (hi - lo)])
    tgt = np.array([ox + 0.6 * w, oy + 0.6 * d, oz + lo])
    return View(eye, tgt, 60.0, width, height, near or max(0.5, size * 1e-5), far or size * 8 + (hi - lo) * 4)


def stress_view(hf: HeightField, kind: str, width: int = 320, height: int = 180, tile_size: int = 64):
    """(terrain, view) for a stress view kind; offset kinds move the terrain (and the camera with it)."""
    w, d = hf.extent
    ox, oy, oz = hf.origin
    lo, hi = hf.height_range
    size = max(w, d)
    far = size * 8 + (hi - lo) * 4
    g = lambda x, y: float(hf.ground_height(x, y))  # noqa: E731
    if kind == "grazing":
        x, y = ox + 0.3 * w, oy + 0.35 * d
        z = g(x, y) + 2.0
        # near 2 cm: on steep ground (x100 exaggeration) the surface passes within centimetres of the eye
        return hf, View(np.array([x, y, z]), np.array([x + w, y + 0.7 * d, z]), 60.0, width, height, 0.02, far)
    if kind == "down":
        c = [ox + 0.5 * w, oy + 0.5 * d]
        return hf, View(np.array(c + [oz + hi + 0.3 * size]), np.array(c + [oz + lo]), 60.0, width, height, 1.0, far)
    if kind == "inside_aabb":
        # lowest sample of the central tile-sized block, eye halfway between it and the block's top
        n = min(tile_size, hf.rows - 1, hf.cols - 1)
        i0, j0 = (hf.rows - 1 - n) // 2, (hf.cols - 1 - n) // 2
        block = hf.heights[i0 : i0 + n + 1, j0 : j0 + n + 1]
        i, j = np.unravel_index(np.argmin(block), block.shape)
        x, y = ox + (j0 + j) * hf.spacing_x, oy + (i0 + i) * hf.spacing_y
        z = g(x, y) + max(0.5 * (float(block.max()) + oz - g(x, y)), 2.0)
        eye, tgt = np.array([x, y, z]), np.array([x + 0.3 * w, y + 0.2 * d, g(x, y)])
        return hf, View(eye, tgt, 70.0, width, height, 0.5, far)
    if kind == "below":
        x, y = ox + 0.5 * w, oy + 0.5 * d
        z = g(x, y) - 20.0
        return hf, View(np.array([x, y, z]), np.array([x + w, y + 0.3 * d, z]), 60.0, width, height, 0.5, far)
    if kind in ("axis_x", "axis_y"):
        z = oz + hi + 0.05 * size
        if kind == "axis_x":
            e, t = [ox + 0.05 * w, oy + 0.5 * d, z], [ox + 0.95 * w, oy + 0.5 * d, oz + lo]
        else:
            e, t = [ox + 0.5 * w, oy + 0.05 * d, z], [ox + 0.5 * w, oy + 0.95 * d, oz + lo]
        return hf, View(np.array(e), np.array(t), 60.0, width, height, 0.5, far)
    if kind in ("offset_1e6", "offset_1e7"):
        off = np.array([1e6, 1e6, 0.0]) if kind == "offset_1e6" else np.array([1e7, 1e7, 0.0])
        moved = hf.moved(np.array(hf.origin) + off)
        return moved, _oblique(hf, width, height).moved(off)
    if kind == "near_far":
        return hf, _oblique(hf, width, height, near=1e-3, far=1e9)
    if kind == "origin":
        return hf, _oblique(hf, width, height)
    raise TerrabenchError(f"unknown stress view {kind!r}; choose from {', '.join(VIEWS)}")


def method_renderer(ctx, hf, method: str, tile_size: int):
    """A method's renderer: POLICY, raycast/RECONSTRUCTION, or raster/FULL_RES (a full-resolution rule)."""
    from hybrid.contract import FULL_RES
    from hybrid.renderer import make_renderer

    policy, _, variant = method.partition("/")
    if variant in FULL_RES:
        return make_renderer(ctx, hf, policy, tile_size=tile_size, full_res=variant)
    return make_renderer(ctx, hf, policy, tile_size=tile_size, reconstruction=variant or "triangles")


@dataclass
class StressCase:
    """One measured (scene, view, method)."""

    scene: str
    view: str
    method: str
    row: dict


def measure(result, ref) -> dict:
    """Failure measures of a frame against the reference frame."""
    from .metrics import hole_pixels_in_columns

    m, r = np.isfinite(result.distance), np.isfinite(ref.distance)
    both = m & r
    rel = (
        np.abs(result.distance[both].astype(np.float64) - ref.distance[both]) / ref.distance[both]
        if both.any()
        else np.array([0.0])
    )
    s = result.stats.counters
    rays = float(s.get("rays", 0) or 0)
    # the reference's outline: terrain pixels next to sky; a level of detail within tau pixels may move it
    sky = ~r
    near_sky = sky.copy()
    near_sky[1:] |= sky[:-1]
    near_sky[:-1] |= sky[1:]
    near_sky[:, 1:] |= sky[:, :-1]
    near_sky[:, :-1] |= sky[:, 1:]
    band = r & near_sky
    return {
        "nan_px": int(np.isnan(result.distance).sum()),
        "hole_px": int((r & ~m).sum()),
        "hole_px_strict": int((r & ~m & ~band).sum()),
        "extra_px": int((m & ~r).sum()),
        "crack_px": int(hole_pixels_in_columns(result).sum()),
        "ref_crack_px": int(hole_pixels_in_columns(ref).sum()),
        "depth_rel_p99": float(np.percentile(rel, 99)),
        "depth_rel_max": float(rel.max()),
        "depth_rel_median": float(np.median(rel)),
        "capped": int(s.get("capped", 0) or 0),
        "rays": int(rays),
        "capped_frac": float(s.get("capped", 0) or 0) / rays if rays else 0.0,
        "mean_steps": float(s.get("mean_steps", np.nan) if rays else np.nan),
        "max_steps": float(s.get("max_steps", np.nan) if rays else np.nan),
        "triangles": int(s.get("triangles", 0) or 0),
        "wall_ms": float(s.get("wall_ms", np.nan)),
        "tiles_raster": int(s.get("tiles_raster", 0)),
        "tiles_raycast": int(s.get("tiles_raycast", 0)),
    }


def run_stress(
    ctx,
    scenes=SCENES,
    views=VIEWS,
    methods=METHODS,
    size: int = 257,
    width: int = 320,
    height: int = 180,
    tile_size: int = 64,
    progress=None,
) -> pd.DataFrame:
    """Every (scene, view, method): a row of failure measures; a method that raises is recorded, not fatal."""
    from hybrid.camera.clearance import eye_clearance, eye_too_low
    from hybrid.reference import ReferenceRenderer

    rows = []
    for sc in scenes:
        base = make_scene(sc, size)
        for vk in views:
            hf, view = stress_view(base, vk, width, height, tile_size)
            ref_r = ReferenceRenderer(ctx, hf)
            ref = ref_r.render(view)
            ref_r.release()
            for m in methods:
                # views a user could not give (eye under the ground or within the near plane) are flagged
                clear = eye_clearance(hf, view.eye)
                row = {
                    "scene": sc,
                    "view": vk,
                    "method": m,
                    "eye_clearance_m": clear,
                    "user_refused": eye_too_low(clear, view),
                }
                try:
                    r = method_renderer(ctx, hf, m, tile_size)
                    try:
                        row.update(measure(r.render(view), ref))
                    finally:
                        r.release()
                    row["error"] = ""
                except Exception as exc:  # recorded as the method's failure on this case
                    row["error"] = f"{type(exc).__name__}: {exc}"
                rows.append(row)
                if progress:
                    progress(f"{sc} {vk} {m}")
    return pd.DataFrame(rows)


def stress_table(
    ctx,
    scenes=SCENES,
    views=VIEWS,
    methods=METHODS,
    size: int = 257,
    viewport: tuple[int, int] = (320, 180),
    tile_size: int = 64,
    progress: bool = True,
) -> pd.DataFrame:
    """run_stress with a progress bar on stderr (none when progress is False); viewport is (width, height) px."""
    from .progress import Progress

    bar = Progress(len(scenes) * len(views) * len(methods), 0, progress)
    try:
        return run_stress(ctx, scenes, views, methods, size, *viewport, tile_size, progress=bar.step)
    finally:
        bar.close()


def run_stress_spec(spec, runs_dir, ctx=None, progress: bool = True) -> Path:
    """Run a StressSpec into runs_dir/<name> (spec.json, stress.parquet); returns the run folder."""
    from hybrid.camera.view import parse_size
    from hybrid.gl.context import shared_context

    from .folders import writable_folder

    folder = writable_folder(Path(runs_dir) / spec.name, "run folder")
    remove_stale_temps(folder)  # what a killed stress run left
    write_json(folder / "spec.json", spec.to_dict())
    df = stress_table(
        ctx or shared_context(),
        spec.scenes,
        spec.views,
        spec.methods,
        spec.size_samples,
        parse_size(spec.size, "spec size"),
        spec.tile_size,
        progress,
    )
    write_parquet(folder / "stress.parquet", df)
    return folder
