"""Tile stores, prepared: the pyramid built once, out of core, into a Zarr directory.

``prepare_store`` reads a grid source (``hybrid.terrain.grid_sources``) one band of tile rows at a time and
writes every level's samples (level l keeps every 2^l-th level-0 sample and the last row and column, as
``TilePyramid.tile`` gathers them), each tile's height bounds and its geometric error. Errors are exact, as the
in-memory pyramid's, for levels whose tiles span at most EXACT_SPAN level-0 cells (measured against level 0's
samples, read in pieces); above, a level's error is bounded without level 0 in memory: the coarser surface S_l differs
from level 0 by at most max |S_l - S_(l-1)| (taken at level l-1's samples: both surfaces split cells along the
same diagonal, so S_(l-1)'s triangles refine S_l's and the largest difference sits at a vertex) plus the
children's error. The bound is never below the exact error (tested), so the screen-space bound still holds;
it may refine a little more than the exact error would. Then the raster strategies' node arrays are written
(``store_nodes.build_nodes``; a complete store without them gets them when prepared again). A source's
``source_step`` is recorded in the attributes (``[step, offset]``, or null) when every level-0 sample lies on it, so
the ray caster's 16-bit tiles of the store are exact, as the in-memory grid's are. Progress is kept in
the store's attributes after every band, so an interrupted prepare resumes where it stopped; the store is marked
complete last, with its manifest (every file's size and CRC-32, ``hybrid.terrain.store_manifest``), which a
complete store prepared before manifests gets when prepared again.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.store_manifest import record_manifest
from hybrid.terrain.stored import STORE_FORMAT, STORE_VERSION, _zarr, is_store

from .fans import GPU_BETA
from .quantize import on_step_cells
from .store_blocks import build_blocks
from .store_nodes import build_nodes, node_bands, node_square
from .subsampling import block_reduce, interpolate_clamped

COL_BLOCK = 4096  # about this many columns per piece of a band when measuring errors (memory bound)
EXACT_SPAN = 1024  # levels whose tiles span at most this many level-0 cells get exact errors


def _levels(rows: int, cols: int, n: int) -> int:
    tiles0 = -(-(max(rows, cols) - 1) // n)
    return int(np.ceil(np.log2(tiles0))) if tiles0 > 1 else 0


def _level_shape(rows: int, cols: int, level: int) -> tuple[int, int]:
    k = 1 << level
    return -(-(rows - 1) // k) + 1, -(-(cols - 1) // k) + 1


def _tile_reduce(band: np.ndarray, n: int, fn) -> np.ndarray:
    """Per tile of a band of samples (first row = the tile row's first), fn over its (n+1)-sample span of columns
    and all the band's rows: (tiles across,)."""
    m = fn.reduce(band, axis=0)
    starts = np.arange(0, len(m) - 1, n)
    ends = np.minimum(starts + n, len(m) - 1)
    return fn(fn.reduceat(m, starts), m[ends])


class _Progress:
    def __init__(self, report, total: int):
        self.report, self.total, self.done, self.t0 = report, total, 0, time.perf_counter()

    def step(self, what: str) -> None:
        self.done += 1
        if self.report:
            self.report(self.done, self.total, what, time.perf_counter() - self.t0)


class _Marks:
    """``mark(key, count, what, extra)``: a band's progress recorded in the store's attributes (with ``extra``
    attributes) and reported; after ``stop_after`` bands (tests) it raises KeyboardInterrupt, as an interruption
    would."""

    def __init__(self, g, progress: _Progress, stop_after: int | None):
        self.g, self.progress, self.stop = g, progress, stop_after

    def __call__(self, key: str, count: int, what: str, extra: dict | None = None) -> None:
        p = dict(self.g.attrs["progress"])
        p[key] = count
        self.g.attrs.update({"progress": p, **(extra or {})})
        self.progress.step(what)
        if self.stop is not None:
            self.stop -= 1
            if self.stop <= 0:
                raise KeyboardInterrupt("stopped as asked (stop_after)")


def prepare_store(source, out, tile_size: int = 256, report=None, stop_after: int | None = None) -> Path:
    """Build the tile store of a grid source, node arrays included, into directory ``out`` (resuming an interrupted
    build of the same source); ``report(done, total, what, seconds)`` is called after every band. ``stop_after`` bands (tests)
    raises KeyboardInterrupt, as an interruption would."""
    zarr = _zarr()
    params = _store_params(source, tile_size)
    n, rows, cols = params["tile_size"], params["rows"], params["cols"]
    out = Path(out)
    g = _open_store(zarr, source, out, params)
    if g is None:
        return out
    L = int(g.attrs["max_level"])
    bands = sum(-(-(_level_shape(rows, cols, l)[0] - 1) // n) for l in range(L + 1))
    prog = _Progress(report, 2 * bands + node_bands(node_square(n, L)[0]))  # levels, nodes, blocks
    mark = _Marks(g, prog, stop_after)
    for level in range(L + 1):
        _write_level(g, source, level, rows, cols, n, mark)
    build_nodes(g, rows, cols, n, L, GPU_BETA, mark)
    build_blocks(g, n, L, mark)
    g.attrs.update({"manifest": record_manifest(out), "complete": True})
    return out


def _store_params(source, tile_size) -> dict:
    """What a store is made from (its ``params`` attribute): the source, its size and spacing, the tile size; checked."""
    n = int(tile_size)
    if n < 2 or n & (n - 1):
        raise TerrabenchError(f"tile size must be a power of two >= 2 cells, got {tile_size!r}")
    rows, cols = int(source.rows), int(source.cols)
    if rows < 2 or cols < 2:
        raise TerrabenchError(f"{source.name}: a grid needs at least 2x2 samples, got {rows}x{cols}")
    sx, sy = (source.spacing, source.spacing) if np.isscalar(source.spacing) else tuple(source.spacing)
    return {
        "source": getattr(source, "path", source.name),
        "rows": rows,
        "cols": cols,
        "tile_size": n,
        "spacing": [float(sx), float(sy)],
    }


def _open_store(zarr, source, out: Path, params: dict):
    """The store group at ``out`` to write: the one there (made from the same ``params``, else refused) or a new
    one; None when the one there is complete (its manifest recorded if it was prepared before manifests)."""
    if out.exists() and not is_store(out) and any(out.iterdir()):
        raise TerrabenchError(f"{out}: exists and is not a tile store; choose an empty or new folder")
    if is_store(out):
        g = zarr.open_group(str(out), mode="r+")
        if dict(g.attrs).get("params") != params:
            raise TerrabenchError(
                f"{out}: holds a store of other input or settings ({dict(g.attrs).get('params')}); "
                "choose another folder or remove it"
            )
        if g.attrs.get("complete") and g.attrs.get("nodes") and g.attrs.get("node_blocks"):
            if not g.attrs.get("manifest"):  # prepared before manifests: record what is on disk
                g.attrs.update({"manifest": record_manifest(out)})
            return None
        return g
    n, rows, cols = params["tile_size"], params["rows"], params["cols"]
    g = zarr.open_group(str(out), mode="w")
    g.attrs.update(
        {
            "format": STORE_FORMAT,
            "version": STORE_VERSION,
            "complete": False,
            "params": params,
            "name": source.name,
            "spacing": list(params["spacing"]),
            "origin": [0.0, 0.0, 0.0],
            "tile_size": n,
            "max_level": _levels(rows, cols, n),
            "notes": list(source.notes),
            "made_by": f"terrabench prepare, tiles of {n}",
            "progress": {},
            "height_range": None,
            "source_step": _claimed_step(source),
        }
    )
    return g


def _level_arrays(g, level: int, R: int, C: int, n: int) -> tuple:
    """(samples, zmin, zmax, error) arrays of a level of R x C samples, made if missing."""
    ty_n, tx_n = -(-(R - 1) // n), -(-(C - 1) // n)
    arrays = {}
    for name, shape, chunks, fill in (
        (f"levels/{level}", (R, C), (n, n), np.nan),
        (f"zmin/{level}", (ty_n, tx_n), (ty_n, tx_n), np.nan),
        (f"zmax/{level}", (ty_n, tx_n), (ty_n, tx_n), np.nan),
        (f"error/{level}", (ty_n, tx_n), (ty_n, tx_n), np.nan),
    ):
        arrays[name.split("/")[0]] = (
            g[name]
            if name in g
            else g.create_array(
                name, shape=shape, chunks=chunks, dtype="f4" if name.startswith("levels") else "f8", fill_value=fill
            )
        )
    return arrays["levels"], arrays["zmin"], arrays["zmax"], arrays["error"]


def _write_level(g, source, level: int, rows: int, cols: int, n: int, mark) -> None:
    """Write a level's samples, its tiles' height bounds and errors, a band of tile rows at a time from the first
    band not yet recorded; the height range with level 0's bands."""
    R, C = _level_shape(rows, cols, level)
    ty_n, tx_n = -(-(R - 1) // n), -(-(C - 1) // n)
    lv, zmin, zmax, err = _level_arrays(g, level, R, C, n)
    start = int(dict(g.attrs["progress"]).get(str(level), 0))
    prev = g[f"levels/{level - 1}"] if level else None
    prev_err = np.asarray(g[f"error/{level - 1}"][:]) if level else None
    for ty in range(start, ty_n):
        r0, r1 = ty * n, min(ty * n + n + 1, R)
        if level == 0:
            band = _level0_band(g, source, r0, r1)
            own = np.zeros(tx_n)
        else:
            band, own = _coarse_band(g, prev, level, r0, r1, rows, cols, n)
        lv[r0:r1, :] = band
        if level == 0:
            zmin[ty, :] = _tile_reduce(band, n, np.minimum)
            zmax[ty, :] = _tile_reduce(band, n, np.maximum)
        if level:
            assert prev_err is not None  # read above for every level but 0
            kids = block_reduce(prev_err, 2, np.maximum)[ty]
            err[ty, :] = np.maximum(own, kids) if (n << level) <= EXACT_SPAN else own + kids
        else:
            err[ty, :] = own
        hr = g.attrs["height_range"]
        lo, hi = float(band.min()), float(band.max())
        mark(
            str(level),
            ty + 1,
            f"level {level} band {ty + 1}",
            {"height_range": [min(lo, hr[0]), max(hi, hr[1])] if hr else [lo, hi]} if level == 0 else None,
        )
    if level:  # bounds of a level: its children's, 2 x 2
        zmin[:, :] = block_reduce(np.asarray(g[f"zmin/{level - 1}"][:]), 2, np.minimum)
        zmax[:, :] = block_reduce(np.asarray(g[f"zmax/{level - 1}"][:]), 2, np.maximum)


def _level0_band(g, source, r0: int, r1: int) -> np.ndarray:
    """Rows r0..r1-1 of the source; a claimed ``source_step`` they are not on is dropped from the attributes."""
    band = source.read_rows(r0, r1)
    step = g.attrs.get("source_step")
    on = on_step_cells(band, step) if step else None
    if on is not None and not on.all():  # a claimed step the samples are not on
        g.attrs.update({"source_step": None})
    return band


def _coarse_band(g, prev, level: int, r0: int, r1: int, rows: int, cols: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(samples, own errors per tile) of rows r0..r1-1 of level ``level`` >= 1: every other sample of level
    l-1 (``prev``); errors exact against level 0 where tiles span at most EXACT_SPAN cells, else bounded against
    level l-1 (the children's errors are added by the caller)."""
    R1 = _level_shape(rows, cols, level - 1)[0]
    C = _level_shape(rows, cols, level)[1]
    a0, a1 = 2 * r0, min(2 * (r1 - 1), R1 - 1) + 1  # level l-1 rows under the band
    fine = np.asarray(prev[a0:a1, :], dtype=np.float32)
    idx = np.minimum(2 * np.arange(r1 - r0), a1 - a0 - 1)
    cidx = np.minimum(2 * np.arange(C), fine.shape[1] - 1)
    band = fine[np.ix_(idx, cidx)]
    if (n << level) <= EXACT_SPAN:  # exact: against level 0's samples under the band
        k = 1 << level
        b0, b1 = r0 * k, min((r1 - 1) * k, rows - 1) + 1
        level0 = g["levels/0"]
        own = _band_error(lambda c0, c1, level0=level0, b0=b0, b1=b1: level0[b0:b1, c0:c1], cols, k, n)
    else:  # bounded: against level l-1, plus its error
        own = _band_error(lambda c0, c1, fine=fine: fine[:, c0:c1], fine.shape[1], 2, n)
    return band, own


def _claimed_step(source) -> list | None:
    """The source's ``source_step`` as [step, offset] metres (checked: finite, step > 0), or None."""
    step = getattr(source, "source_step", None)
    if step is None:
        return None
    try:
        s, o = (float(v) for v in step)
    except (TypeError, ValueError):
        raise TerrabenchError(f"{source.name}: source_step must be (step, offset) in metres, got {step!r}") from None
    if not (np.isfinite(s) and np.isfinite(o) and s > 0):
        raise TerrabenchError(
            f"{source.name}: source_step must have a finite step > 0 and a finite offset (metres), got {step!r}"
        )
    return [s, o]


def _band_error(piece_of, cols: int, k: int, n: int) -> np.ndarray:
    """Per level-l tile of a band: the largest |S - G| (metres) over the samples G of a finer grid under the band,
    S the grid of every k-th of them triangulated; ``piece_of(c0, c1)`` gives columns c0..c1-1 of the band's
    rows of that grid (first row on a level-l row). Read in pieces of whole tiles to bound memory."""
    span = k * n  # finer-grid cells a level-l tile spans
    tiles = -(-(cols - 1) // span) if cols > 1 else 1
    out = np.zeros(tiles)
    width = span * max(1, COL_BLOCK // span)
    for c0 in range(0, max(cols - 1, 1), width):
        c1 = min(c0 + width, cols - 1) + 1
        piece = np.asarray(piece_of(c0, c1), dtype=np.float64)
        dev = np.abs(interpolate_clamped(piece, k) - piece)
        if piece.shape[0] > 1 and piece.shape[1] > 1:
            cell = np.maximum(np.maximum(dev[:-1, :-1], dev[:-1, 1:]), np.maximum(dev[1:, :-1], dev[1:, 1:]))
        else:
            cell = dev
        e = block_reduce(cell, span, np.maximum).max(axis=0)
        t0 = c0 // span
        out[t0 : t0 + len(e)] = np.maximum(out[t0 : t0 + len(e)], e)
    return out
