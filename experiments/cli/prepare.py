"""`terrabench prepare`: build a terrain's tile pyramid once, out of core, into a tile store (a Zarr folder)."""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

from . import argtypes
from .options import add_file_arguments

HELP = "build the tile pyramid of a file (or a synthetic terrain) out of core into a tile store"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The prepare options: input (a GDAL file, or --synthetic SIZE), --out, tile size and loader overrides."""
    p.add_argument(
        "input",
        nargs="?",
        default=None,
        help="a height grid: GDAL-readable (GeoTIFF/COG, .hgt, ...), read in bands, or any other file "
        "render takes (.npy, .npz, 16-bit .png, raw), loaded whole",
    )
    p.add_argument("--out", required=True, help="the tile store folder to write (resumed if interrupted)")
    p.add_argument(
        "--synthetic",
        type=argtypes.int_in("--synthetic", 2, 1_048_577),
        default=None,
        metavar="SIZE",
        help="instead of a file: a seeded fractal terrain of SIZE x SIZE samples (e.g. 16385)",
    )
    p.add_argument("--seed", type=argtypes.int_in("--seed", 0, 2**32 - 1), default=0, help="seed of --synthetic")
    p.add_argument(
        "--synthetic-period",
        type=argtypes.int_in("--synthetic-period", 2, 1 << 20),
        default=None,
        help="make --synthetic repeat seamlessly every this many samples (a power of two >= 1024)",
    )
    p.add_argument(
        "--synthetic-spacing",
        type=argtypes.positive_float("--synthetic-spacing", "metres"),
        default=10.0,
        help="metres between samples of --synthetic",
    )
    p.add_argument(
        "--tile-size", type=argtypes.power_of_two("--tile-size"), default=256, help="cells per tile side (power of two)"
    )
    add_file_arguments(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _bar(done: int, total: int, what: str, seconds: float) -> None:
    frac = done / max(total, 1)
    left = seconds / done * (total - done) if done else float("nan")
    line = f"[{'#' * int(30 * frac):30s}] {done}/{total} bands, {what}, {seconds:.0f} s, about {left:.0f} s left"
    end = "\r" if sys.stderr.isatty() and done < total else "\n"
    if sys.stderr.isatty() or done == total or done % max(total // 10, 1) == 0:
        sys.stderr.write(line + end)
        sys.stderr.flush()


def _file_source(path, vertical_scale=None, spacing=None, crs=None, crop=None, raw_shape=None, raw_dtype=None):
    """The grid source of a height-field file: GDAL formats read in row bands, every other file render takes
    (.npy, .npz, 16-bit .png, raw) loaded whole by the same loader."""
    from hybrid.errors import TerrabenchError
    from hybrid.terrain.grid_sources import GdalGridSource, HeightFieldSource
    from hybrid.terrain.loaders import SUFFIXES, load_terrain
    from hybrid.terrain.paths import path_problem

    problem = path_problem(path)
    if problem is not None:
        raise TerrabenchError(f"{path}: {problem}")
    if not Path(path).is_file():
        raise TerrabenchError(f"{path}: not a file")
    kind = SUFFIXES.get(Path(path).suffix.lower(), "gdal")
    if kind == "gdal" and raw_shape is None and raw_dtype is None:
        return GdalGridSource(path, vertical_scale=vertical_scale, spacing=spacing, crs=crs, crop=crop)
    opts = {"vertical_scale": vertical_scale, "spacing": spacing, "crs": crs, "crop": crop}
    if raw_shape is not None or raw_dtype is not None:
        opts.update(shape=None if raw_shape is None else tuple(raw_shape), dtype=raw_dtype)
    return HeightFieldSource(load_terrain(path, **opts))


SQUARE_NOTE_RATIO = 16  # node arrays over a square this many times the grid's samples: say so first


def square_note(rows: int, cols: int, tile_size: int) -> str | None:
    """A warning when a store's node arrays, built over the square of whole root tiles around the grid, would
    cover SQUARE_NOTE_RATIO times the grid's samples or more (an elongated grid), else None."""
    from hybrid.tiles.store_nodes import node_square

    cells = max(rows, cols) - 1
    tiles0 = -(-cells // tile_size)
    level = int(np.ceil(np.log2(tiles0))) if tiles0 > 1 else 0
    square = (node_square(tile_size, level)[0] + 1) ** 2
    if square < SQUARE_NOTE_RATIO * rows * cols:
        return None
    return (
        f"note: {cols}x{rows} samples: the raster strategies' node arrays cover the square of whole tiles "
        f"around the grid, {square / (rows * cols):.0f}x its samples, so this prepare's time and disk grow with "
        f"that square, not with the grid; a grid that fits in memory draws with every method without prepare"
    )


def run(
    input=None,
    out="store",
    synthetic=None,
    seed=0,
    synthetic_spacing=10.0,
    tile_size=256,
    vertical_scale=None,
    spacing=None,
    crs=None,
    crop=None,
    quiet=False,
    synthetic_period=None,
    raw_shape=None,
    raw_dtype=None,
) -> Path:
    """Build (or finish) the tile store of the input at ``out``; prints the time and the process's peak RSS."""
    from hybrid.errors import TerrabenchError
    from hybrid.terrain.grid_sources import FractalSource
    from hybrid.tiles.store import prepare_store

    if (input is None) == (synthetic is None):
        raise TerrabenchError("give an input file or --synthetic SIZE (one of them)")
    if synthetic is not None:
        source = FractalSource(synthetic, seed, synthetic_spacing, period=synthetic_period)
    else:
        source = _file_source(input, vertical_scale, spacing, crs, crop, raw_shape, raw_dtype)
    note = square_note(source.rows, source.cols, int(tile_size))
    if note:
        sys.stderr.write(note + "\n")
    t0 = time.perf_counter()
    path = prepare_store(source, out, tile_size, None if quiet else _bar)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    print(
        f"tile store {path}: {source.cols}x{source.rows} samples, tiles of {tile_size}; "
        f"{time.perf_counter() - t0:.1f} s, peak RSS {rss:.2f} GiB"
    )
    return path


def run_from_args(args: argparse.Namespace) -> int:
    """The prepare command from parsed arguments; returns the exit code."""
    run(
        args.input,
        args.out,
        args.synthetic,
        args.seed,
        args.synthetic_spacing,
        args.tile_size,
        args.vertical_scale,
        args.spacing,
        args.crs,
        args.crop,
        args.quiet,
        args.synthetic_period,
        args.raw_shape,
        args.raw_dtype,
    )
    return 0
