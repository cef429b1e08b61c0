"""`terrabench render`: one view with one method to PATH.png and PATH.depth.npy (and PATH.strategy.png)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from hybrid.contract import DEFAULT_FULL_RES
from hybrid.errors import TerrabenchError
from hybrid.strategies import (
    adapting_policies,
    methods,
    mixed_policies,
    option_choices,
    policies_taking,
    strategies_of_kind,
)

from ..folders import writable_folder
from . import argtypes
from .options import TerrainOptions, ViewOptions, add_terrain_arguments, add_view_arguments, from_args

HELP = "render one view with a method to PNG + depth (.depth.npy)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The render options: terrain, view, method, output and the strategies' draw options."""
    add_terrain_arguments(p)
    add_view_arguments(p)
    p.add_argument("--method", default="reference", choices=methods())
    p.add_argument("--out", required=True, help="output PNG path; the depth goes to PATH.depth.npy")
    p.add_argument("--shading", default=None, help="texture, shaded or height (default: texture if present)")
    p.add_argument(
        "--supersample",
        type=argtypes.int_in("--supersample", 1, 8),
        default=1,
        help="reference colour supersampling factor (1..8)",
    )
    p.add_argument(
        "--tau",
        type=argtypes.positive_float("--tau", "pixels"),
        default=2 / 3,
        help="screen-space error bound in pixels (> 0)",
    )
    p.add_argument(
        "--tile-size",
        type=argtypes.power_of_two("--tile-size"),
        default=None,
        help="cells per tile side (power of two; default 256, or a tile store's own)",
    )
    _add_ray_arguments(p)
    _add_raster_arguments(p)
    p.add_argument("--show-strategy", action="store_true", help="hybrid: also write PATH.strategy.png")
    p.add_argument(
        "--edit",
        type=Path,
        default=None,
        metavar="FILE.jsonl",
        help="replay this edit log (JSON lines, made for this terrain) on the GPU before rendering",
    )
    p.add_argument(
        "--freeze-model",
        action="store_true",
        help="hybrid: choose by the loaded cost model as it is (no online refit from the frames drawn)",
    )


def _add_ray_arguments(p: argparse.ArgumentParser) -> None:
    """The ray-cast draw options: reconstruction, traversal, pre-pass, LOD and shadows."""
    recs = option_choices("reconstruction")
    p.add_argument("--reconstruction", default="triangles", help=f"ray-cast surface: {', '.join(recs)}")
    p.add_argument("--traversal", default="maxmip", help="ray-cast traversal: maxmip or naive (level-0 stepping)")
    pre = p.add_mutually_exclusive_group()
    pre.add_argument(
        "--prepass",
        dest="prepass",
        action="store_const",
        const=True,
        default=None,
        help="ray casting with the tile-ID pre-pass (default: off; it paid on no device measured)",
    )
    pre.add_argument(
        "--no-prepass",
        dest="prepass",
        action="store_const",
        const=False,
        help="ray casting without the tile-ID pre-pass",
    )
    p.add_argument("--lod", action="store_true", help="ray casting stops descending at tau pixels (LOD)")
    p.add_argument("--shadows", action="store_true", help="ray-cast shadow rays toward the light")


def _add_raster_arguments(p: argparse.ArgumentParser) -> None:
    """The raster draw options: wireframe, lean leaves and the full-resolution rule."""
    p.add_argument("--wireframe", action="store_true", help="raster methods: draw edges only")
    p.add_argument(
        "--no-lean",
        dest="lean",
        action="store_false",
        help="raster, raster_gs (and their tiles in mixed policies): every leaf keeps the edge midpoints "
        "that only lean leaves drop (those no finer neighbour and no near split needs)",
    )
    p.add_argument(
        "--full-res",
        choices=option_choices("full_res"),
        default=DEFAULT_FULL_RES,
        help="raster, raster_gs (and their tiles in mixed policies): full-resolution leaves drop "
        "midpoints by their errors as other leaves do (lean: no more triangles than the bound asks "
        "for), or keep every midpoint, cells split as the reference's (exact: more triangles, "
        "closer to the reference at a given tau)",
    )


def draw_options(
    method: str,
    tau: float,
    shading=None,
    reconstruction="triangles",
    traversal="maxmip",
    prepass=None,
    lod=False,
    shadows=False,
    wireframe=False,
    lean=True,
    full_res=DEFAULT_FULL_RES,
) -> dict:
    """Strategy draw options for a method (only those asked for, so the rest stay the strategy's defaults)."""
    opts = {}
    if shading:
        opts["mode"] = shading
    if method == "raycast":
        opts.update(reconstruction=reconstruction, traversal=traversal)
        if prepass is not None:
            opts["prepass"] = prepass
        if shadows:
            opts["shadows"] = True
        if lod:
            opts["lod"] = tau
    elif shadows or lod or prepass is not None or traversal != "maxmip":
        raise TerrabenchError(
            "--shadows, --lod, --prepass, --no-prepass and --traversal apply to --method raycast only"
        )
    if method in mixed_policies():
        opts.update(reconstruction=reconstruction, **({} if prepass is None else {"prepass": prepass}))
    if wireframe:
        if method not in strategies_of_kind("raster"):
            raise TerrabenchError("--wireframe applies to the raster methods (raster, fullres, tin)")
        opts["wireframe"] = True
    if not lean:
        if method not in policies_taking("lean"):
            raise TerrabenchError(
                "--no-lean applies to raster, raster_gs and the mixed policies (hybrid, heuristic, oracle)"
            )
        opts["lean"] = False
    if full_res != DEFAULT_FULL_RES:
        if method not in policies_taking("full_res"):
            raise TerrabenchError(
                "--full-res applies to raster, raster_gs and the mixed policies (hybrid, heuristic, oracle)"
            )
        opts["full_res"] = full_res
    return opts


def run(
    out,
    method: str = "reference",
    terrain: TerrainOptions = TerrainOptions(),
    view: ViewOptions = ViewOptions(),
    shading: str | None = None,
    supersample: int = 1,
    tau: float = 2 / 3,
    tile_size: int | None = None,
    reconstruction: str = "triangles",
    traversal: str = "maxmip",
    prepass: bool | None = None,
    lod: bool = False,
    shadows: bool = False,
    wireframe: bool = False,
    show_strategy: bool = False,
    device: int | None = None,
    lean: bool = True,
    full_res: str = DEFAULT_FULL_RES,
    freeze_model: bool = False,
    edit: Path | None = None,
):
    """Render one view with a method, after replaying the edit log ``edit`` if given; write out (.png) and its
    .depth.npy; returns the RenderResult."""
    from hybrid.gl.context import shared_context

    out = _checked_out(out, method, show_strategy, freeze_model)
    hf = terrain.load()
    log = _checked_log(edit, hf)
    if tile_size is None:
        tile_size = int(hf.store.attrs["tile_size"]) if getattr(hf, "store", None) is not None else 256
    ctx = shared_context(device)
    if method == "reference":
        from hybrid.reference import ReferenceRenderer

        with ReferenceRenderer(ctx, hf) as r:
            _replay(ctx, hf, log, reference=r)
            result = r.render(view.view(hf), mode=shading, supersample=supersample)
    else:
        from hybrid.renderer import Renderer

        opts = draw_options(
            method, tau, shading, reconstruction, traversal, prepass, lod, shadows, wireframe, lean, full_res
        )
        with Renderer(ctx, hf, method, tile_size, adapt=not freeze_model, **opts) as r:
            _replay(ctx, hf, log, renderer=r)
            v = view.view(hf)
            result = r.render(v, tau, maps=show_strategy)
    v = view.view(hf)
    png, depth = _write_outputs(result, out, show_strategy)
    _print_result(method, result, v, png, depth)
    return result


def _checked_log(edit: Path | None, hf):
    """The edit log at ``edit`` (None: none), checked whole against the terrain before anything is drawn or
    written."""
    if edit is None:
        return None
    from hybrid.terrain.edit_log import check_log, read_log

    return check_log(read_log(edit), hf, str(edit))


def _write_outputs(result, out: Path, show_strategy: bool) -> tuple:
    """Write the frame's PNG and depth (and with ``show_strategy`` its strategy map beside them); the two paths."""
    from hybrid.atomic import remove_stale_temps

    remove_stale_temps(out.parent)  # what a killed render left beside its output
    png, depth = result.save(out)
    if show_strategy:
        smap = out.parent / (out.stem + ".strategy.png")
        save_strategy_map(result, smap)
        print(f"strategy map: {smap} (blue raster, orange ray cast)")
    return png, depth


def _checked_out(out, method: str, show_strategy: bool, freeze_model: bool) -> Path:
    """The output PNG path, its folder writable; refuses options the method does not take."""
    from hybrid.gl.target import check_png_path

    out = check_png_path(out, "--out")
    writable_folder(out.parent if str(out.parent) else Path("."), "--out folder")
    if show_strategy and method not in mixed_policies():
        raise TerrabenchError("--show-strategy needs a mixed policy: --method hybrid (or heuristic, oracle)")
    if freeze_model and method not in adapting_policies():
        raise TerrabenchError("--freeze-model applies to --method hybrid, the one policy that refits its cost model")
    return out


def _print_result(method: str, result, v, png, depth) -> None:
    """Say what was written, how much of the view shows terrain, and the frame's stats."""
    cover = float(result.mask.mean()) * 100
    print(f"{method}: wrote {png} and {depth} ({v.width}x{v.height}, terrain on {cover:.1f} % of pixels)")
    for k, val in result.stats.row().items():
        if not isinstance(val, (list, dict)):
            print(f"  {k}: {val:.4g}" if isinstance(val, float) else f"  {k}: {val}")


def _replay(ctx, hf, log, **renderers) -> None:
    """Replay an edit log (None: nothing) on the GPU, the renderers following; print what the edits cost."""
    if log is None:
        return
    from hybrid.editing import TerrainEditor, replay

    with TerrainEditor(ctx, hf, **renderers) as editor:
        reports = replay(editor, log)
    total: dict = {}
    for rep in reports:
        for k, ms in rep.ms.items():
            total[k] = total.get(k, 0.0) + ms
    steps = ", ".join(f"{k} {ms:.1f}" for k, ms in total.items())
    print(f"replayed {len(reports)} edits: {steps} ms in all")


def run_from_args(args: argparse.Namespace) -> int:
    """The render command from parsed arguments; returns the exit code."""
    run(
        args.out,
        args.method,
        from_args(TerrainOptions, args),
        from_args(ViewOptions, args),
        args.shading,
        args.supersample,
        args.tau,
        args.tile_size,
        args.reconstruction,
        args.traversal,
        args.prepass,
        args.lod,
        args.shadows,
        args.wireframe,
        args.show_strategy,
        args.device,
        args.lean,
        args.full_res,
        args.freeze_model,
        args.edit,
    )
    return 0


def save_strategy_map(result, path: Path) -> None:
    """Write the per-pixel strategy map blended over the frame: blue = raster tile, orange = ray-cast tile."""
    from hybrid.atomic import save_png

    m = result.maps["strategy"]
    col = result.colour.astype(np.float32)
    tint = np.zeros_like(col)
    tint[m == 1] = (40, 110, 255)
    tint[m == 2] = (255, 140, 20)
    mix = np.where((m > 0)[..., None], 0.45 * col + 0.55 * tint, col)
    save_png(path, np.clip(mix, 0, 255).astype(np.uint8))
