"""`terrabench scale`: the scaling experiment over tile stores of growing size, and its report."""

from __future__ import annotations

import argparse
from pathlib import Path

from . import argtypes

HELP = "frame time and memory of each method over tile stores of growing size (Dick et al. Figs. 9-10)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The scale options: stores, frames, viewport, tau, methods, budgets and where the report goes."""
    p.add_argument(
        "stores",
        nargs="+",
        help="tile stores (terrabench prepare), or STORE@periodicSIZE for a virtual "
        "periodic extension of one to SIZE x SIZE samples (SIZE = k x its cells + 1)",
    )
    p.add_argument("--frames", type=argtypes.int_in("--frames", 2, 10000), default=48, help="frames of the flight")
    p.add_argument(
        "--flight",
        default="transect",
        help="preset flight, scaled to each store's extent (transect: straight and level, new tiles all along)",
    )
    p.add_argument("--size", type=argtypes.size("--size"), default="640x360", help="viewport WIDTHxHEIGHT")
    p.add_argument(
        "--tau",
        type=argtypes.positive_float("--tau", "pixels"),
        default=2 / 3,
        help="screen-space error bound in pixels",
    )
    p.add_argument("--methods", type=argtypes.words("--methods"), default="raycast,raster,raster_gs,hybrid")
    p.add_argument("--gpu-budget-mib", type=argtypes.int_in("--gpu-budget-mib", 1, 1 << 20), default=256)
    p.add_argument(
        "--upload-budget-ms",
        type=argtypes.positive_float("--upload-budget-ms", "ms"),
        default=8.0,
        help="uploads run inside each frame within this many ms (streaming)",
    )
    p.add_argument(
        "--resident",
        action="store_true",
        help="instead of streaming: upload each frame's tiles before it (untimed), as terrain already on the GPU",
    )
    p.add_argument(
        "--jump-frames",
        type=argtypes.int_in("--jump-frames", 0, 10000),
        default=40,
        help="also jump the camera on each store and count, over this many frames, the share of tiles drawn at "
        "their wanted level (0: no jump)",
    )
    p.add_argument("--host-budget-mib", type=argtypes.int_in("--host-budget-mib", 1, 1 << 20), default=512)
    p.add_argument("--out", default="reports/scaling", help="report folder")


def run(
    stores,
    frames=48,
    flight="transect",
    size=(640, 360),
    tau=2 / 3,
    methods=("raycast", "raster", "raster_gs", "hybrid"),
    gpu_budget_mib=256,
    upload_budget_ms=8.0,
    host_budget_mib=512,
    out="reports/scaling",
    device=None,
    resident=False,
    jump_frames=40,
) -> Path:
    """Run the experiment and write its report; returns the report's path."""
    from hybrid.errors import TerrabenchError
    from hybrid.gl.context import gl_info, shared_context

    from ..folders import writable_folder
    from ..scaling import METHODS, run_scaling
    from ..scaling_report import write_scaling_report

    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise TerrabenchError(f"--methods: unknown {', '.join(bad)}; choose from {', '.join(METHODS)}")
    writable_folder(Path(out).parent if str(Path(out).parent) else Path("."), "--out")
    ctx = shared_context(device)
    budget = None if resident else upload_budget_ms
    frames_df, refused, setup = run_scaling(
        ctx, stores, frames, size, tau, methods, gpu_budget_mib, budget, host_budget_mib, flight
    )
    uploads = (
        "resident: each frame's missing tiles uploaded before it, untimed"
        if resident
        else f"streaming: uploads within {upload_budget_ms:g} ms a frame, inside its time"
    )
    notes = [
        f"{flight} flight of {frames} frames at {size[0]}x{size[1]}, tau {tau:.3g} px, each frame drawn once",
        f"GPU budget {gpu_budget_mib} MiB; {uploads}; host tile cache {host_budget_mib} MiB",
        "GPU memory: the exact sizes of the buffers and textures terrabench allocated (not a driver reading)",
    ]
    jumps = None
    if jump_frames and not resident:
        from ..stream_jump import jump_table, run_jumps

        budgets = {
            "upload_budget_ms": upload_budget_ms,
            "gpu_budget_mib": gpu_budget_mib,
            "host_budget_mib": host_budget_mib,
        }
        jumps = jump_table(run_jumps(ctx, stores, methods, jump_frames, size, tau, **budgets))
        notes.append(
            f"camera jump: every tile of the transect's first view resident, then its last view, {jump_frames} "
            "frames drawn once each, streaming as above"
        )
    path = write_scaling_report(frames_df, refused, setup, Path(out), gl_info(ctx).renderer, notes, jumps)
    print(f"report: {path}")
    return path


def run_from_args(args: argparse.Namespace) -> int:
    """The scale command from parsed arguments; returns the exit code."""
    run(
        args.stores,
        args.frames,
        args.flight,
        args.size,
        args.tau,
        args.methods,
        args.gpu_budget_mib,
        args.upload_budget_ms,
        args.host_budget_mib,
        args.out,
        args.device,
        args.resident,
        args.jump_frames,
    )
    return 0
