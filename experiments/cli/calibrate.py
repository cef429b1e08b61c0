"""`terrabench calibrate`: time tiles both ways on this device, fit the cost model, report its error, save it."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..folders import writable_folder
from . import argtypes
from .options import TerrainOptions, add_terrain_arguments, from_args

HELP = "time tiles both ways on this device and fit the cost model"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The calibrate options: terrain, flights and views, tau, tile size, repeats, hold-out share and saving."""
    add_terrain_arguments(p)
    p.add_argument(
        "--flights",
        type=argtypes.words("--flights"),
        default="flyover,orbit",
        help="comma-separated flights to sample views from",
    )
    p.add_argument("--frames", type=argtypes.int_in("--frames", 1, 1000), default=6, help="views per flight")
    p.add_argument("--size", type=argtypes.size("--size"), default="640x360", help="viewport WIDTHxHEIGHT")
    p.add_argument(
        "--tau",
        type=argtypes.positive_float("--tau", "pixels"),
        default=2 / 3,
        help="screen-space error bound in pixels",
    )
    p.add_argument(
        "--tile-size", type=argtypes.power_of_two("--tile-size"), default=256, help="cells per tile side (power of two)"
    )
    p.add_argument(
        "--repeats",
        type=argtypes.int_in("--repeats", 1, 100),
        default=3,
        help="timed draws per tile and strategy (median)",
    )
    p.add_argument("--holdout", type=float, default=0.3, help="share of timed frames held out to measure the fit")
    p.add_argument("--save", default="user", help="'user' (default costs file), a path, or '' for no save")
    p.add_argument(
        "--key",
        default=None,
        help="save under this key instead of the full GL renderer string "
        "(the shipped defaults use a substring such as 'llvmpipe')",
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="calibrate every device of this Dask cluster (one worker per GL renderer)",
    )
    p.add_argument(
        "--scheduler-timeout",
        type=argtypes.positive_float("--scheduler-timeout", "seconds"),
        default=None,
        metavar="SECONDS",
        help="seconds to wait for --scheduler to answer (default 5)",
    )
    where.add_argument("--workers", default=None, metavar="local:N", help="calibrate on a local Dask cluster")


def run(
    terrain: TerrainOptions = TerrainOptions(),
    flights=("flyover", "orbit"),
    frames: int = 6,
    size: tuple[int, int] = (640, 360),
    tau: float = 2 / 3,
    tile_size: int = 256,
    repeats: int = 3,
    holdout: float = 0.3,
    save: str | None = "user",
    key: str | None = None,
    device: int | None = None,
    scheduler: str | None = None,
    workers: str | None = None,
    scheduler_timeout: float | None = None,
):
    """Calibrate the cost model on views of the flights (size in pixels, tau in pixels); returns the fitted models
    (one, or one per device of a cluster)."""
    from hybrid.cost.model import save_cost_model
    from hybrid.gl.context import shared_context

    if save and save != "user":
        writable_folder(Path(save).parent if str(Path(save).parent) else Path("."), "--save folder")
    args = (terrain, tuple(flights), frames, size, tau, tile_size, repeats, holdout)
    if scheduler or workers:
        from ..cluster import CONNECT_TIMEOUT_S, calibrate_on_cluster, connect

        client, cluster = connect(scheduler, workers, scheduler_timeout or CONNECT_TIMEOUT_S)
        try:
            models = calibrate_on_cluster(client, args)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    else:
        from ..calibration import calibrate_here

        models = [calibrate_here(shared_context(device), *args).model]
    for model in models:
        print(model.explain())
        if save:
            if key and len(models) == 1:
                model.renderer = key
            print(f"saved to {save_cost_model(model, Path(save) if save != 'user' else None)}")
    return models


def run_from_args(args: argparse.Namespace) -> int:
    """The calibrate command from parsed arguments; returns the exit code."""
    run(
        from_args(TerrainOptions, args),
        args.flights,
        args.frames,
        args.size,
        args.tau,
        args.tile_size,
        args.repeats,
        args.holdout,
        args.save,
        args.key,
        args.device,
        args.scheduler,
        args.workers,
        args.scheduler_timeout,
    )
    return 0
