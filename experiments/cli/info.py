"""`terrabench info`: the GL renderer, and what a terrain file, dataset or tile store holds (tiles, levels)."""

from __future__ import annotations

import argparse

from . import argtypes
from .options import TerrainOptions, add_terrain_arguments, from_args

HELP = "GL renderer and, given a file or --dataset, what was loaded"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The info options: an optional terrain file or dataset, tile size, and --no-gl."""
    p.add_argument("file", nargs="?", default=None, help="a height-field file to describe")
    add_terrain_arguments(p)
    p.set_defaults(dataset=None)  # no terrain is described unless one is named
    p.add_argument(
        "--tile-size", type=argtypes.power_of_two("--tile-size"), default=256, help="cells per tile side (power of two)"
    )
    p.add_argument("--no-gl", dest="gl", action="store_false", help="do not open a GL context")
    p.add_argument(
        "--verify",
        action="store_true",
        help="a tile store: check every file against its manifest (exit 2 listing the damaged ones)",
    )


def run(
    terrain: TerrainOptions | None = None,
    tile_size: int = 256,
    gl: bool = True,
    device: int | None = None,
    verify: bool = False,
) -> None:
    """Print the terrain's summary and tiling (when one is given; a tile store's own, ``verify`` checking its files)
    and the GL context's renderer (unless gl=False)."""
    from hybrid.errors import TerrabenchError
    from hybrid.terrain.stored import is_store, store_remains

    store = terrain is not None and (is_store(terrain.dataset) or store_remains(terrain.dataset))
    if verify and not store:
        raise TerrabenchError("--verify applies to a tile store (terrabench info STORE --verify)")
    if store:
        assert terrain is not None  # store implies a terrain
        from .store_info import describe_store

        describe_store(terrain.dataset, verify)
    elif terrain is not None:
        from hybrid.tiles.pyramid import TilePyramid

        hf = terrain.load()
        print(hf.summary())
        pyr = TilePyramid(hf, tile_size)
        print(
            f"tiles:       {tile_size} cells, levels 0..{pyr.max_level}, "
            f"{sum(len(pyr.keys(l)) for l in range(pyr.max_level + 1))} tiles"
        )
    if gl:
        from hybrid.gl.context import gl_info, shared_context

        info = gl_info(shared_context(device))
        print(f"GL renderer: {info.renderer}\nGL vendor:   {info.vendor}\nGL version:  {info.version}")


def run_from_args(args: argparse.Namespace) -> int:
    """The info command from parsed arguments; returns the exit code."""
    terrain = None
    if args.file or args.dataset:
        args.dataset = args.file or args.dataset
        terrain = from_args(TerrainOptions, args)
    run(terrain, args.tile_size, args.gl, args.device, args.verify)
    return 0
