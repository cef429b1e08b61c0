"""The `terrabench` command line: one entry point with subcommands.

Every user error ends with one line `terrabench: error: ...` naming the argument and exit code 2;
nothing is written before the inputs are checked.
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

from hybrid.errors import TerrabenchError

METHODS = ("reference", "raster", "raycast", "hybrid", "heuristic", "oracle", "fullres", "tin")


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        self.print_usage(sys.stderr)
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def _vec(text: str, name: str) -> np.ndarray:
    try:
        v = [float(s) for s in text.split(",")]
    except ValueError:
        raise TerrabenchError(f"--{name} must be three numbers x,y,z in metres, got {text!r}") from None
    if len(v) != 3:
        raise TerrabenchError(f"--{name} must be three numbers x,y,z in metres, got {text!r}")
    return np.array(v)


def _size(text: str) -> tuple[int, int]:
    from hybrid.camera.view import parse_size
    return parse_size(text, "--size")


def check_tile_size(n) -> int:
    """--tile-size must be a power of two in [2, 4096] cells."""
    if not (2 <= n <= 4096) or n & (n - 1):
        raise TerrabenchError(f"--tile-size must be a power of two in [2, 4096] cells, got {n}")
    return n


def writable_folder(path: Path, what: str) -> Path:
    """Create the folder if needed and prove it writable with a probe file; else a clear error."""
    import tempfile
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".terrabench-probe-"):
            pass
    except OSError as exc:
        raise TerrabenchError(f"{what} {path} is not a writable folder ({exc.strerror or exc})") from None
    return path


def add_terrain_args(p: argparse.ArgumentParser) -> None:
    """Options naming a terrain: bundled/synthetic name or a file, with scale and spacing overrides."""
    p.add_argument("--dataset", default="puget", help="bundled name (puget, fbm, ridged, spike, cliff, staircase, flat, ridges) or a file")
    p.add_argument("--size-samples", type=int, default=None, help="samples per side for synthetic data, or a crop of puget")
    p.add_argument("--seed", type=int, default=0, help="seed for synthetic data")
    p.add_argument("--vertical-scale", type=float, default=None, help="metres per stored unit (files)")
    p.add_argument("--spacing", type=float, default=None, help="metres between samples (files)")
    p.add_argument("--raw-shape", default=None, help="ROWSxCOLS for raw files")
    p.add_argument("--raw-dtype", default=None, help="NumPy dtype for raw files, e.g. <u2, <f4")
    p.add_argument("--offset", default=None, help="place the terrain at world x,y,z metres")


def load_terrain_arg(args):
    """The HeightField named by --dataset (and friends)."""
    from hybrid.terrain.datasets import NAMES, get_dataset
    from hybrid.terrain.loaders import load_terrain
    name = args.dataset
    if name in NAMES:
        hf = get_dataset(name, size=args.size_samples, seed=args.seed)
    elif Path(name).suffix:
        opts = {"vertical_scale": args.vertical_scale, "spacing": args.spacing}
        if args.raw_shape:
            try:
                opts["shape"] = tuple(int(s) for s in args.raw_shape.lower().split("x"))
            except ValueError:
                raise TerrabenchError(f"--raw-shape must be ROWSxCOLS, got {args.raw_shape!r}") from None
            opts["dtype"] = args.raw_dtype
        hf = load_terrain(name, **opts)
    else:
        raise TerrabenchError(f"unknown dataset {name!r}; choose one of {', '.join(NAMES)} or give a file path")
    if getattr(args, "offset", None):
        hf = hf.moved(_vec(args.offset, "offset"))
    return hf


def add_view_args(p: argparse.ArgumentParser) -> None:
    """Options choosing the view: eye/target/fov/size or a flight frame."""
    p.add_argument("--eye", default=None, help="eye x,y,z in world metres")
    p.add_argument("--target", default=None, help="look-at point x,y,z in world metres")
    p.add_argument("--fov", type=float, default=60.0, help="vertical field of view in degrees, (0, 180)")
    p.add_argument("--size", default="640x360", help="viewport WIDTHxHEIGHT in pixels")
    p.add_argument("--near", type=float, default=None, help="near plane in metres")
    p.add_argument("--far", type=float, default=None, help="far plane in metres")
    p.add_argument("--flight", default=None, help="preset (orbit, flyover, grazing, lookdown) or a .json/.csv flight")
    p.add_argument("--frames", type=int, default=60, help="frames of a preset flight")
    p.add_argument("--frame", type=int, default=0, help="frame of the flight to render")


def view_from_args(args, hf):
    """The View named by the view options."""
    from hybrid.camera.flight import get_flight
    from hybrid.camera.view import View, default_view
    w, h = _size(args.size)
    if args.flight:
        if args.eye or args.target:
            raise TerrabenchError("give either --flight or --eye/--target, not both")
        v = get_flight(args.flight, hf, frames=args.frames, width=w, height=h).view(args.frame, w, h)
    elif args.eye or args.target:
        if not (args.eye and args.target):
            raise TerrabenchError("--eye and --target must be given together")
        d = default_view(hf, 16, 16)
        v = View(_vec(args.eye, "eye"), _vec(args.target, "target"), args.fov, w, h,
                 args.near if args.near is not None else d.near, args.far if args.far is not None else d.far)
        return v
    else:
        v = default_view(hf, w, h, args.fov)
    if args.near is not None or args.far is not None or args.fov != v.fov_y:
        v = View(v.eye, v.target, args.fov, v.width, v.height,
                 args.near if args.near is not None else v.near, args.far if args.far is not None else v.far)
    return v


def cmd_info(args) -> int:
    """Print the GL context (and the terrain when a file or dataset is named)."""
    from hybrid.gl.context import gl_info, shared_context
    if args.file or args.dataset_given:
        if args.file:
            args.dataset = args.file
        hf = load_terrain_arg(args)
        print(hf.summary())
        from hybrid.tiles.pyramid import TilePyramid
        pyr = TilePyramid(hf, args.tile_size)
        print(f"tiles:       {args.tile_size} cells, levels 0..{pyr.max_level}, "
              f"{sum(len(pyr.keys(l)) for l in range(pyr.max_level + 1))} tiles")
    if not args.no_gl:
        info = gl_info(shared_context(args.device))
        print(f"GL renderer: {info.renderer}\nGL vendor:   {info.vendor}\nGL version:  {info.version}")
    return 0


def render_method(ctx, hf, view, method: str, args):
    """Render one view with a method; returns a RenderResult."""
    if method == "reference":
        from hybrid.reference import ReferenceRenderer
        with ReferenceRenderer(ctx, hf) as r:
            return r.render(view, mode=args.shading, supersample=args.supersample)
    from hybrid.renderer import Renderer
    opts = draw_options(args, method)
    if method in ("hybrid", "heuristic", "oracle"):
        opts.update(reconstruction=args.reconstruction, prepass=not args.no_prepass)
    with Renderer(ctx, hf, method, args.tile_size, **opts) as r:
        return r.render(view, args.tau, maps=args.show_strategy)


def draw_options(args, method: str) -> dict:
    """Strategy draw options from the command line (only those the user gave, so defaults stay the strategy's)."""
    opts = {}
    if args.shading:
        opts["mode"] = args.shading
    if method == "raycast":
        opts["reconstruction"] = args.reconstruction
        opts["traversal"] = args.traversal
        opts["prepass"] = not args.no_prepass
        if args.shadows:
            opts["shadows"] = True
        if args.lod:
            opts["lod"] = args.tau
    elif args.shadows or args.lod or args.no_prepass or args.traversal != "maxmip":
        raise TerrabenchError("--shadows, --lod, --no-prepass and --traversal apply to --method raycast only")
    if args.wireframe:
        if method not in ("raster", "fullres", "tin"):
            raise TerrabenchError("--wireframe applies to the raster methods (raster, fullres, tin)")
        opts["wireframe"] = True
    return opts


def cmd_render(args) -> int:
    """Render one view with a method; write PATH.png and PATH.depth.npy."""
    from hybrid.errors import check_positive
    from hybrid.gl.context import shared_context
    out = Path(args.out)
    if out.suffix.lower() != ".png":
        raise TerrabenchError(f"--out must end in .png, got {args.out!r}")
    folder = out.parent if str(out.parent) else Path(".")
    if not folder.is_dir():
        raise TerrabenchError(f"--out folder {folder} does not exist")
    writable_folder(folder, "--out folder")
    check_positive("--tau (pixels)", args.tau)
    check_tile_size(args.tile_size)
    if args.show_strategy and args.method not in ("hybrid", "heuristic", "oracle"):
        raise TerrabenchError("--show-strategy needs a mixed policy: --method hybrid (or heuristic, oracle)")
    hf = load_terrain_arg(args)
    view = view_from_args(args, hf)
    ctx = shared_context(args.device)
    result = render_method(ctx, hf, view, args.method, args)
    png, depth = result.save(out)
    if args.show_strategy:
        smap = out.parent / (out.stem + ".strategy.png")
        save_strategy_map(result, smap)
        print(f"strategy map: {smap} (blue raster, orange ray cast)")
    cover = float(result.mask.mean()) * 100
    print(f"{args.method}: wrote {png} and {depth} ({view.width}x{view.height}, terrain on {cover:.1f} % of pixels)")
    for k, v in result.stats.row().items():
        if isinstance(v, (list, dict)):
            continue
        print(f"  {k}: {v:.4g}" if isinstance(v, float) else f"  {k}: {v}")
    return 0


def cmd_run(args) -> int:
    """Run (or resume) an experiment spec."""
    from .runner import run_spec
    from .spec import load_spec
    spec = load_spec(args.spec)
    if args.name:
        spec.name = args.name
    writable_folder(Path(args.runs), "--runs")
    if args.report:
        writable_folder(Path(args.reports), "--reports")
    from .spec import StressSpec
    if isinstance(spec, StressSpec):
        from .stress import write_stress_report
        folder = writable_folder(Path(args.runs) / spec.name, "run folder")
        import json
        (folder / "spec.json").write_text(json.dumps(spec.to_dict(), indent=1))
        df = _stress_table(args, spec.scenes, spec.views, spec.methods, spec.size_samples, _size(spec.size),
                           spec.tile_size)
        df.to_parquet(folder / "stress.parquet", index=False)
        print(f"run folder: {folder}")
        if args.report:
            print(f"report: {write_stress_report(df, Path(args.reports) / spec.name)}")
        return 0
    folder = run_spec(spec, Path(args.runs), progress=not args.quiet)
    print(f"run folder: {folder}")
    if args.report:
        from .report import write_report
        print(f"report: {write_report(folder, Path(args.reports), video=spec.video)}")
    return 0


def cmd_report(args) -> int:
    """Write the report of a run folder (and the flight animations with --video)."""
    from .report import write_report
    if (Path(args.run) / "stress.parquet").exists():
        import pandas as pd
        from .stress import write_stress_report
        out = writable_folder(Path(args.reports) / (args.name or Path(args.run).name), "--reports")
        print(f"wrote {write_stress_report(pd.read_parquet(Path(args.run) / 'stress.parquet'), out)}")
        return 0
    if not (Path(args.run) / "frames.parquet").exists():
        raise TerrabenchError(f"{args.run}: not a run folder with results (no frames.parquet); run `terrabench run SPEC` first")
    writable_folder(Path(args.reports), "--reports")
    path = write_report(Path(args.run), Path(args.reports), args.name, video=args.video)
    print(f"wrote {path} and {path.with_suffix('.html')}")
    return 0


def cmd_calibrate(args) -> int:
    """Time tiles both ways on this device, fit the cost model, report held-out error, save it."""
    from hybrid.calibrate import calibrate
    from hybrid.cost.model import save_cost_model
    from hybrid.errors import check_positive
    from hybrid.camera.flight import get_flight
    from hybrid.gl.context import shared_context
    check_positive("--tau (pixels)", args.tau)
    if not (1 <= args.frames <= 1000):
        raise TerrabenchError(f"--frames must lie in [1, 1000], got {args.frames}")
    if not (1 <= args.repeats <= 100):
        raise TerrabenchError(f"--repeats must lie in [1, 100], got {args.repeats}")
    check_tile_size(args.tile_size)
    if args.save and args.save != "user":
        writable_folder(Path(args.save).parent if str(Path(args.save).parent) else Path("."), "--save folder")
    hf = load_terrain_arg(args)
    w, h = _size(args.size)
    views = []
    for name in args.flights.split(","):
        views += get_flight(name.strip(), hf, frames=args.frames, width=w, height=h).views()
    ctx = shared_context(args.device)
    cal = calibrate(ctx, hf, views, args.tau, args.tile_size, args.repeats, args.holdout)
    print(cal.model.explain())
    if args.save:
        if args.key:
            cal.model.renderer = args.key
        print(f"saved to {save_cost_model(cal.model, Path(args.save) if args.save != 'user' else None)}")
    return 0


def _names(text: str, allowed, what: str) -> list[str]:
    names = [t.strip() for t in text.split(",") if t.strip()]
    bad = [n for n in names if n not in allowed]
    if not names or bad:
        raise TerrabenchError(f"--{what}: unknown {bad or text!r}; choose from {', '.join(allowed)}")
    return names


def _stress_table(args, scenes, views, methods, size_samples, size, tile_size):
    """Run the stress cases with a progress bar (unless --quiet); the table of failure measures."""
    from hybrid.gl.context import shared_context
    from .runner import Progress
    from .stress import run_stress
    bar = Progress(len(scenes) * len(views) * len(methods), 0, not args.quiet)
    df = run_stress(shared_context(args.device), scenes, views, methods, size_samples, *size, tile_size,
                    progress=bar.step)
    bar.close()
    return df


def cmd_stress(args) -> int:
    """Run the stress scenes and views with every method; write the table, chart and report section."""
    from .stress import METHODS, SCENES, VIEWS, write_stress_report
    scenes = _names(args.scenes, SCENES, "scenes")
    views = _names(args.views, VIEWS, "views")
    methods = _names(args.methods, METHODS, "methods")
    size = _size(args.size)
    if not (17 <= args.size_samples <= 4097):
        raise TerrabenchError(f"--size-samples must lie in [17, 4097], got {args.size_samples}")
    out = writable_folder(Path(args.out), "--out")
    df = _stress_table(args, scenes, views, methods, args.size_samples, size, args.tile_size)
    print(f"wrote {write_stress_report(df, out)}")
    return 0


BENCHES = ("raycast", "raster", "hybrid")


def cmd_bench(args) -> int:
    """Run the raster, ray-cast and hybrid benchmarks in one process and print (and save) their tables."""
    import contextlib
    import io
    from hybrid.gl.context import gl_info, shared_context
    which = _names(args.which, BENCHES, "which")
    info = gl_info(shared_context(args.device))
    out = Path(args.out) if args.out else None
    if out is not None:
        writable_folder(out.parent if str(out.parent) else Path("."), "--out folder")
    if not (1 <= args.frames <= 1000):
        raise TerrabenchError(f"--frames must lie in [1, 1000], got {args.frames}")
    import os
    import platform
    head = (f"# terrabench benchmarks\n\ndevice: {info.renderer} ({info.version}); CPU cores: {os.cpu_count()}; "
            f"{platform.platform()}\n")
    print(head)
    text = [head]
    for name in which:
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            if name == "raycast":
                from .bench_raycast import main as run
                run(["--frames", str(args.frames)])
            elif name == "raster":
                from .bench_raster import main as run
                run()
            else:
                from .bench_hybrid import main as run
                run(["--frames", str(args.frames)])
        section = f"## {name}\n\n```\n{buf.getvalue().rstrip()}\n```\n"
        print(section)
        text.append(section)
    if out is not None:
        out.write_text("\n".join(text))
        print(f"wrote {out}")
    return 0


def save_strategy_map(result, path: Path) -> None:
    """Write the per-pixel strategy map blended over the frame: blue = raster tile, orange = ray-cast tile."""
    from PIL import Image
    m = result.maps["strategy"]
    col = result.colour.astype(np.float32)
    tint = np.zeros_like(col)
    tint[m == 1] = (40, 110, 255)
    tint[m == 2] = (255, 140, 20)
    mix = np.where((m > 0)[..., None], 0.45 * col + 0.55 * tint, col)
    Image.fromarray(np.clip(mix, 0, 255).astype(np.uint8)).save(path)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand."""
    p = _Parser(prog="terrabench", description="Rasterize meshes or ray-cast the height field, tile by tile: "
                "render, measure and compare on real elevation data.")
    p.add_argument("--device", type=int, default=None, help="EGL device index (or TERRABENCH_GL_DEVICE)")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    pi = sub.add_parser("info", help="GL renderer and, given a file or --dataset, what was loaded")
    pi.add_argument("file", nargs="?", default=None, help="a height-field file to describe")
    add_terrain_args(pi)
    pi.add_argument("--tile-size", type=int, default=256)
    pi.add_argument("--no-gl", action="store_true", help="do not open a GL context")
    pi.set_defaults(func=cmd_info)

    pr = sub.add_parser("render", help="render one view with a method to PNG + depth (.depth.npy)")
    add_terrain_args(pr)
    add_view_args(pr)
    pr.add_argument("--method", default="reference", choices=METHODS)
    pr.add_argument("--out", required=True, help="output PNG path; the depth goes to PATH.depth.npy")
    pr.add_argument("--shading", default=None, help="texture, shaded or height (default: texture if present)")
    pr.add_argument("--supersample", type=int, default=1, help="reference colour supersampling factor (1..8)")
    pr.add_argument("--tau", type=float, default=2 / 3, help="screen-space error bound in pixels (> 0)")
    pr.add_argument("--tile-size", type=int, default=256, help="cells per tile side (power of two)")
    pr.add_argument("--reconstruction", default="triangles", help="ray-cast surface: planes, linear, triangles, bilinear")
    pr.add_argument("--traversal", default="maxmip", help="ray-cast traversal: maxmip or naive (level-0 stepping)")
    pr.add_argument("--no-prepass", action="store_true", help="ray casting without the tile-ID pre-pass")
    pr.add_argument("--lod", action="store_true", help="ray casting stops descending at tau pixels (LOD)")
    pr.add_argument("--shadows", action="store_true", help="ray-cast shadow rays toward the light")
    pr.add_argument("--wireframe", action="store_true", help="raster methods: draw edges only")
    pr.add_argument("--show-strategy", action="store_true", help="hybrid: also write PATH.strategy.png")
    pr.set_defaults(func=cmd_render)

    pn = sub.add_parser("run", help="run an experiment spec (TOML): paired flights, tables, images")
    pn.add_argument("spec", help="experiment spec file (.toml) or a bundled one: default, tiny, stress")
    pn.add_argument("--runs", default="runs", help="folder that holds run folders")
    pn.add_argument("--name", default=None, help="run name (default: the spec's)")
    pn.add_argument("--report", action="store_true", help="write the report when done")
    pn.add_argument("--reports", default="reports", help="folder for reports")
    pn.add_argument("--quiet", action="store_true", help="no progress bar")
    pn.set_defaults(func=cmd_run)

    pp = sub.add_parser("report", help="write reports/<name>/report.md + .html from a run folder")
    pp.add_argument("run", help="run folder (runs/<name>)")
    pp.add_argument("--reports", default="reports", help="folder for reports")
    pp.add_argument("--name", default=None, help="report name (default: the run's)")
    pp.add_argument("--video", action="store_true", help="also write the flight as GIF animations (spec video = true)")
    pp.set_defaults(func=cmd_report)

    pc = sub.add_parser("calibrate", help="time tiles both ways on this device and fit the cost model")
    add_terrain_args(pc)
    pc.add_argument("--flights", default="flyover,orbit", help="comma-separated flights to sample views from")
    pc.add_argument("--frames", type=int, default=6, help="views per flight")
    pc.add_argument("--size", default="640x360", help="viewport WIDTHxHEIGHT")
    pc.add_argument("--tau", type=float, default=2 / 3, help="screen-space error bound in pixels")
    pc.add_argument("--tile-size", type=int, default=256)
    pc.add_argument("--repeats", type=int, default=3, help="timed draws per tile and strategy (median)")
    pc.add_argument("--holdout", type=float, default=0.3, help="share of tiles held out to measure the fit")
    pc.add_argument("--save", default="user", help="'user' (default costs file), a path, or '' for no save")
    pc.add_argument("--key", default=None, help="save under this key instead of the full GL renderer string "
                    "(the shipped defaults use a substring such as 'llvmpipe')")
    pc.set_defaults(func=cmd_calibrate)

    from .stress import METHODS as SM, SCENES as SS, VIEWS as SV
    ps = sub.add_parser("stress", help="scenes and views that break methods: failure table, chart, report section")
    ps.add_argument("--scenes", default=",".join(SS), help="comma-separated: " + ", ".join(SS))
    ps.add_argument("--views", default=",".join(SV), help="comma-separated: " + ", ".join(SV))
    ps.add_argument("--methods", default=",".join(SM), help="comma-separated: " + ", ".join(SM))
    ps.add_argument("--size-samples", type=int, default=257, help="samples a side of each scene")
    ps.add_argument("--size", default="320x180", help="viewport WIDTHxHEIGHT")
    ps.add_argument("--tile-size", type=int, default=64, help="cells per tile side")
    ps.add_argument("--out", default="reports/stress", help="folder for stress.md, the chart and the table")
    ps.add_argument("--quiet", action="store_true")
    ps.set_defaults(func=cmd_stress)

    pb = sub.add_parser("bench", help="the raster, ray-cast and hybrid benchmarks in one run, with the device named")
    pb.add_argument("--which", default=",".join(BENCHES), help="comma-separated: " + ", ".join(BENCHES))
    pb.add_argument("--frames", type=int, default=8, help="frames of each flight")
    pb.add_argument("--out", default=None, help="also write the tables to this markdown file")
    pb.set_defaults(func=cmd_bench)
    return p


def main(argv=None) -> int:
    """Run the command line; returns the exit code (2 for user errors)."""
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    args.dataset_given = "--dataset" in argv
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            return int(args.func(args) or 0)
    except TerrabenchError as exc:
        print(f"terrabench: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
