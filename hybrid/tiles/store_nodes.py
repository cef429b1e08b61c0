"""The raster strategies' node arrays of a tile store, built out of core (``prepare_store`` calls ``build_nodes``).

They are the arrays ``raster.nodes.GlobalNodes`` holds (``global_nodes``: nodes split on their full fans' errors,
with their stitched triangles' errors as side codes, ``hybrid.tiles.sidecodes``), over the same padded square of
R = N * 2^L cells (the grid's edge samples repeated): per global level g (nodes of 2^(g+1) level-0 cells,
(R >> (g+1))² of them) ``nodes/effective/<g>`` (saturated effective error, metres), ``nodes/sides/<g>`` (the
side codes against level g+1's effective errors), ``nodes/zlo/<g>`` and ``nodes/zhi/<g>`` (height range of the
node's box, its square grown by its side, metres relative to the origin z), float32, chunked; and
``nodes/combined/<g>``, the saturated error of the combined form (``global_nodes(side_errors=False)``: one error
over both fans, which bounds every side), from which a periodic extension takes the bounds of its nodes near its
seams (``hybrid.tiles.periodic_nodes``).

How, band by band:
- Direct errors, levels whose nodes span at most NODE_EXACT_SPAN cells: blocks of that many cells of the padded
  square are read from level 0 (clamped at the grid's edges) and every fan deviation is measured at every
  sample (``hybrid.tiles.fans``: the same floating-point operations as over the whole square), the full fan's,
  both fans' and each stitched triangle's, so these errors and codes are exactly those of ``global_nodes``.
- Larger nodes are bounded, not measured: for x in child C of node P, |F_P(x) - h(x)| <= |F_P(x) - F_C(x)| +
  |F_C(x) - h(x)|. C's full fan refines both of P's fans on C (its eight triangles are cut by C's diagonals
  and midlines, and P's fans are linear on each of them), so |F_P - F_C| peaks at C's 3x3 posts, where F_C is
  the samples: the bound is P's fan deviation at the level-(g-1) posts plus the child's error (exact or bound),
  plus 16 ulps of the largest height for float64 rounding, rounded up to float32. It is never below the exact
  value (tested), so a node never splits later than it should; it may split earlier. These levels hold at most
  (R / 2048)² nodes, so each is computed whole, from the posts of the stored level nearest below. With the
  child's full-fan error the bound is one of both of P's fans, so of every side too (its four side errors).
- Then per level, from the level below: errors made monotone and raised to the side errors facing the node,
  effective errors saturated (``dilate4``, 1/beta, the facing sides too), each form in turn, height ranges
  min/max of the children, boxes the 3x3 range (``grow3``), each band reading its rows plus an apron; a level's
  side codes once its parents' float32 errors are written. Intermediate float64 arrays live in ``nodes/tmp``
  until the last level is written.

Progress is recorded after every band (attribute ``progress``), so an interrupted build resumes; the store's
``nodes`` attribute (beta, levels, square, exact span, form "sides") is written when all levels are.
"""

from __future__ import annotations

import numpy as np

from .fans import (
    block2,
    cell_centre_error,
    cell_max,
    dilate4,
    facing_side_errors,
    fan_deviation,
    fan_deviations,
    grow3,
    side_maxima,
    with_cell_centres,
)
from .sidecodes import SIDE_FORM, holds_side_codes, side_codes

NODE_EXACT_SPAN = 1024  # node sides (level-0 cells) up to which node errors are measured exactly
SLICE_ROWS = 128  # sample rows measured at once inside a block (memory bound)
NODE_BAND = 1 << 19  # nodes per band of a level's pass (memory bound)
SIDE_NODES = 1 << 17  # nodes whose side errors are worked on at once (memory bound: 4 float64 each)
CHUNK = 512  # chunk side of the build's working arrays (nodes)
MIN_CHUNK = 8  # smallest chunk side of the final node arrays (nodes)


def node_square(n: int, max_level: int) -> tuple[int, int]:
    """(R, levels): cells a side of the padded square of tiles of n cells up to max_level, and its global node
    levels."""
    R = n << max_level
    return R, int(np.log2(R))


def _plan(R: int) -> tuple[int, int]:
    """(block side in cells, last exact global level)."""
    B = min(NODE_EXACT_SPAN, R)
    return B, int(np.log2(B)) - 1


def _band_rows(total: int, exact: bool) -> int:
    return max(1, NODE_BAND // total) if exact else total


def node_bands(R: int) -> int:
    """Bands the node build records (for the progress total)."""
    B, gx = _plan(R)
    levels = int(np.log2(R))
    out = R // B
    for g in range(levels):
        total = R >> (g + 1)
        out += 2 * -(-total // _band_rows(total, g <= gx))
    return out + 1  # the top level's side codes


def _window(lv0, rows: int, cols: int, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    """Samples rows r0..r1-1, columns c0..c1-1 of the padded square (float64), read from level 0 clamped."""
    ri, ci = np.minimum(np.arange(r0, r1), rows - 1), np.minimum(np.arange(c0, c1), cols - 1)
    a0, c_0 = int(ri[0]), int(ci[0])
    w = np.asarray(lv0[a0 : int(ri[-1]) + 1, c_0 : int(ci[-1]) + 1], dtype=np.float64)
    return w[np.ix_(ri - a0, ci - c_0)]


def _array(g, name: str, total: int, dtype: str, chunk: int = CHUNK, planes: int = 0):
    """The store's (total, total) array ``name`` ((planes, total, total) with ``planes``), made if missing."""
    if name in g:
        return g[name]
    c = min(total, chunk)
    lead = (planes,) if planes else ()
    return g.create_array(
        name,
        shape=lead + (total, total),
        chunks=lead + (c, c),
        dtype=dtype,
        fill_value=np.nan,
        **_TMP if name.startswith("nodes/tmp/") else {},
    )


_TMP = {"compressors": None}  # intermediate arrays, read back once or twice and deleted: not worth compressing


def tile_chunk(n: int, level: int) -> int:
    """Chunk side (nodes) of global node level ``level`` in a store of n-cell tiles: the nodes a level-0 tile
    has there (at least MIN_CHUNK), so a tile's window and its one-node apron read a few small chunks."""
    return max(MIN_CHUNK, n >> (level + 1))


def _direct_block(lv0, rows, cols, R, B, gx, br, c0) -> tuple[list, list, list, np.ndarray, np.ndarray]:
    """One block of B x B cells (band br, first column c0): per exact level ((B / s)² nodes) the direct errors of
    both fans together, of the full fan alone and of the stitched fan's four triangles ((4, B / s, B / s), level
    0's with the cell centres' terms), and level 0's node height ranges."""
    r0 = br * B
    shape = [(B >> (g + 1), B >> (g + 1)) for g in range(gx + 1)]
    direct, full = [np.zeros(sh) for sh in shape], [np.zeros(sh) for sh in shape]
    sides = [np.zeros((4,) + sh) for sh in shape]
    S = min(SLICE_ROWS, B)
    w = _window(lv0, rows, cols, r0, r0 + B + 1, c0, c0 + B + 1)
    cols_idx = np.arange(c0, c0 + B + 1)
    cmin = np.minimum(np.minimum(w[:-1, :-1], w[:-1, 1:]), np.minimum(w[1:, :-1], w[1:, 1:]))
    cmax = np.maximum(np.maximum(w[:-1, :-1], w[:-1, 1:]), np.maximum(w[1:, :-1], w[1:, 1:]))
    zmin, zmax = block2(cmin, np.min).astype(np.float32), block2(cmax, np.max).astype(np.float32)
    del cmin, cmax
    for g in range(gx + 1):
        s = 2 << g
        for i0 in range(0, B, S):
            rows_idx = np.arange(r0 + i0, r0 + i0 + S + 1)
            df, ds = fan_deviations(w, r0, c0, rows_idx, cols_idx, g, R)
            sr = min(s, S)
            a = i0 // s
            for out, dev in ((direct[g], np.maximum(df, ds)), (full[g], df)):
                part = cell_max(dev).reshape(S // sr, sr, B // s, s).max(axis=(1, 3))
                np.maximum(out[a : a + part.shape[0]], part, out=out[a : a + part.shape[0]])
            part = side_maxima(ds, g, i0 % s if S < s else 0)
            np.maximum(sides[g][:, a : a + part.shape[1]], part, out=sides[g][:, a : a + part.shape[1]])
    sides[0] = with_cell_centres(w, sides[0])
    direct[0] = np.maximum(direct[0], cell_centre_error(w))
    return direct, full, sides, zmin, zmax


def _post_deviation(levels_of, R: int, L: int, lev: int) -> np.ndarray:
    """Per level-(lev-1) node: level ``lev``'s fan deviation (both fans, metres, float64) at its 3x3 posts, read
    from the stored level ``levels_of(l)`` nearest below (every 2^l-th sample, the last row and column kept)."""
    l = min(lev - 1, L)
    arr = np.asarray(levels_of(l)[:, :], dtype=np.float64)
    P = (R >> (lev - 1)) + 1
    p = np.arange(P)
    q = p << (lev - 1 - l)
    H = arr[np.ix_(np.minimum(q, arr.shape[0] - 1), np.minimum(q, arr.shape[1] - 1))]
    return block2(cell_max(fan_deviation(H, 0, 0, p, p, 1, P - 1)), np.max)  # per child: its 3x3 posts


def _facing(sides_below, a0: int, a1: int, total: int) -> np.ndarray:
    """Per node of rows a0..a1-1 of a level (``total`` rows), the largest facing side error of the level below
    (``facing_side_errors``, its 2 x 2 maximum), from that level's (4, 2 total, cols) side errors read with an even
    apron of two rows, so each row's neighbours are those of the whole level; a few rows at a time (memory)."""
    step = max(1, SIDE_NODES // max(sides_below.shape[2], 1) // 2)
    out = []
    for b0 in range(a0, a1, step):
        b1 = min(b0 + step, a1)
        lo, hi = max(2 * b0 - 2, 0), min(2 * b1 + 2, 2 * total)
        f = facing_side_errors(np.asarray(sides_below[:, lo:hi, :]))[2 * b0 - lo : 2 * b1 - lo]
        out.append(block2(f, np.max))
    return np.concatenate(out, axis=0)


KINDS = ("error", "eff", "serror", "seff", "zmin", "zmax")
"""A level's working arrays: both fans' errors and effective errors, the full fan's, and the height range."""


class _Build:
    """A node build of store group ``g``: the padded square of R cells, its working arrays (``nodes/tmp``), the
    bands recorded and ``mark``, which records one more."""

    def __init__(self, g, R: int, n: int, max_level: int, beta: float, mark):
        self.g, self.R, self.n, self.max_level, self.beta, self.mark = g, R, n, max_level, beta, mark
        hr = g.attrs["height_range"]
        self.margin = 16 * np.finfo(np.float64).eps * max(abs(float(hr[0])), abs(float(hr[1])), 1.0)

    def progress(self, key: str) -> int:
        """Bands recorded under ``key``."""
        return int(dict(self.g.attrs["progress"]).get(key, 0))

    @staticmethod
    def tmp(kind: str, lev: int) -> str:
        """The name of a level's working array of ``kind``."""
        return f"nodes/tmp/{kind}/{lev}"

    def work(self, kind: str, lev: int, dtype: str = "f8"):
        """Level ``lev``'s working array of ``kind``, made if missing."""
        return _array(self.g, self.tmp(kind, lev), self.R >> (lev + 1), dtype)

    def sides(self, lev: int):
        """Level ``lev``'s side errors (4, total, total), made if missing."""
        return _array(self.g, self.tmp("sides", lev), self.R >> (lev + 1), "f8", planes=4)


def build_nodes(g, rows: int, cols: int, n: int, max_level: int, beta: float, mark) -> None:
    """Write the node arrays of a store group ``g`` whose levels are written; ``mark(key, count, what)`` records
    a band's progress (and may raise KeyboardInterrupt)."""
    R, levels = node_square(n, max_level)
    B, gx = _plan(R)
    if g.attrs.get("nodes") and not holds_side_codes(g):
        return  # complete arrays of the combined form (prepared before side codes): kept
    b = _Build(g, R, n, max_level, beta, mark)
    if b.progress("nodes:direct") and b.tmp("full", 0) not in g:  # a build begun before side codes: begin again
        g.attrs.update({"progress": {k: v for k, v in dict(g.attrs["progress"]).items() if not k.startswith("nodes")}})
        if "nodes/tmp" in g:
            del g["nodes/tmp"]
    _direct_errors(b, rows, cols, B, gx)
    for lev in range(levels):
        _build_level(b, lev, lev <= gx)
    if not b.progress("nodes:codes"):  # the root level's: no parent
        top = levels - 1
        _write_codes(g, b.sides(top), top, 0, 1, None, tile_chunk(n, top))
        mark("nodes:codes", 1, "side codes")
    g.attrs.update({"nodes": {"beta": float(beta), "levels": levels, "square": R, "exact_span": B, "form": SIDE_FORM}})
    if "nodes/tmp" in g:
        del g["nodes/tmp"]


def _direct_errors(b: _Build, rows: int, cols: int, B: int, gx: int) -> None:
    """The exact levels' direct errors and side errors and level 0's height ranges into the working arrays, a band
    of B x B blocks at a time, from the first band not yet recorded."""
    lv0, R = b.g["levels/0"], b.R
    for br in range(b.progress("nodes:direct"), R // B):
        for c0 in range(0, R, B):  # a block of B x B cells at a time
            direct, full, sides, zmin, zmax = _direct_block(lv0, rows, cols, R, B, gx, br, c0)
            for lev, (d, f, sd) in enumerate(zip(direct, full, sides)):
                at = (slice(br * d.shape[0], (br + 1) * d.shape[0]), slice(c0 >> (lev + 1), (c0 + B) >> (lev + 1)))
                b.work("direct", lev)[at] = d
                b.work("full", lev)[at] = f
                b.sides(lev)[(slice(None),) + at] = sd
            for kind, z in (("zmin", zmin), ("zmax", zmax)):
                b.work(kind, 0, "f4")[br * (B // 2) : (br + 1) * (B // 2), c0 // 2 : (c0 + B) // 2] = z
        b.mark("nodes:direct", br + 1, f"node errors, band {br + 1}")


def _build_level(b: _Build, lev: int, exact: bool) -> None:
    """Global level ``lev``'s node arrays in two passes of bands, from the first band not yet recorded: errors,
    effective errors and ranges (``_level_band``), then the final float32 arrays (``_final_band``)."""
    total = b.R >> (lev + 1)
    hb = _band_rows(total, exact)
    starts = list(range(0, total, hb))
    key = f"nodes:{lev}"
    done = b.progress(key)
    if done >= 2 * len(starts):
        return
    arr = {k: _array(b.g, b.tmp(k, lev), total, "f4" if k.startswith("z") else "f8") for k in KINDS}
    below = {k: b.g[b.tmp(k, lev - 1)] for k in KINDS} if lev else None
    for i, a0 in enumerate(starts):  # pass 1: errors, effective errors, ranges
        if i < done:
            continue
        a1 = min(a0 + hb, total)
        if below is None:
            for k, src in (("error", "direct"), ("eff", "direct"), ("serror", "full"), ("seff", "full")):
                arr[k][a0:a1, :] = np.asarray(b.g[b.tmp(src, 0)][a0:a1, :])
            arr["zmin"][a0:a1, :] = np.asarray(b.g[b.tmp("zmin", 0)][a0:a1, :])
            arr["zmax"][a0:a1, :] = np.asarray(b.g[b.tmp("zmax", 0)][a0:a1, :])
        else:
            _level_band(b, lev, exact, arr, below, a0, a1)
        b.mark(key, i + 1, f"node level {lev}, band {i + 1}")
    final = {
        k: _array(b.g, f"nodes/{k}/{lev}", total, "f4", tile_chunk(b.n, lev))
        for k in ("effective", "combined", "zlo", "zhi")
    }
    for i, a0 in enumerate(starts):  # pass 2: float32 errors, 3x3 box ranges, codes
        if len(starts) + i < done:
            continue
        _final_band(b, lev, exact, arr, final, a0, min(a0 + hb, total))
        b.mark(key, len(starts) + i + 1, f"node boxes {lev}, band {i + 1}")


def _level_band(b: _Build, lev: int, exact: bool, arr: dict, below: dict, a0: int, a1: int) -> None:
    """Rows a0..a1-1 of level ``lev`` >= 1's working arrays from the level below: the combined form's errors and
    effective errors (both fans in one error), the side-error form's (full fans, sides facing), height ranges."""
    total = b.R >> (lev + 1)
    facing = _facing(b.sides(lev - 1), a0, a1, total)
    post = None if exact else _post_deviation(lambda l: b.g[f"levels/{l}"], b.R, b.max_level, lev)
    lo, hi = max(2 * a0 - 1, 0), min(2 * a1 + 1, 2 * total)
    # the combined form (both fans in one error), then the side-error form (full fans, sides facing)
    for err, eff, direct, with_sides in (("error", "eff", "direct", False), ("serror", "seff", "full", True)):
        kids = np.asarray(below[err][2 * a0 : 2 * a1, :])
        if exact:
            e = np.maximum(np.asarray(b.g[b.tmp(direct, lev)][a0:a1, :]), block2(kids, np.max))
        else:  # a bound of both fans, so of every side too
            e = block2(post + kids, np.max) + b.margin
            if with_sides:
                b.sides(lev)[:, a0:a1, :] = np.broadcast_to(e, (4,) + e.shape)
        del kids
        d = block2(dilate4(np.asarray(below[eff][lo:hi, :]))[2 * a0 - lo : 2 * a1 - lo], np.max)
        if with_sides:
            e = np.maximum(e, facing)
            d = np.maximum(d, facing)
        arr[err][a0:a1, :] = e
        arr[eff][a0:a1, :] = np.maximum(e, d / b.beta)
        del e, d
    arr["zmin"][a0:a1, :] = block2(np.asarray(below["zmin"][2 * a0 : 2 * a1, :]), np.min)
    arr["zmax"][a0:a1, :] = block2(np.asarray(below["zmax"][2 * a0 : 2 * a1, :]), np.max)


def _final_band(b: _Build, lev: int, exact: bool, arr: dict, final: dict, a0: int, a1: int) -> None:
    """Rows a0..a1-1 of level ``lev``'s final arrays: float32 errors (bounds rounded up), the 3x3 box ranges, and
    the level below's side codes against these errors."""
    total = b.R >> (lev + 1)
    e32 = {}
    for kind, src in (("effective", "seff"), ("combined", "eff")):
        e64 = np.asarray(arr[src][a0:a1, :])
        e32[kind] = e64.astype(np.float32)
        if not exact:  # a bound stays a bound in float32
            e32[kind] = np.where(e32[kind] < e64, np.nextafter(e32[kind], np.float32(np.inf)), e32[kind])
        final[kind][a0:a1, :] = e32[kind]
    lo, hi = max(a0 - 1, 0), min(a1 + 1, total)
    for kind, src, fn in (("zlo", "zmin", np.minimum), ("zhi", "zmax", np.maximum)):
        # the slab's own edges repeat only where they are the square's; other rows are the apron
        final[kind][a0:a1, :] = grow3(np.asarray(arr[src][lo:hi, :]), fn)[a0 - lo : a1 - lo]
    if lev:  # the level below's side codes, against these errors
        _write_codes(b.g, b.sides(lev - 1), lev - 1, 2 * a0, 2 * a1, e32["effective"], tile_chunk(b.n, lev - 1))


def _write_codes(g, sides, lev: int, r0: int, r1: int, parent, chunk: int) -> None:
    """Rows r0..r1-1 (r0 even) of level ``lev``'s side codes (``nodes/sides/<lev>``, float32) from its side errors,
    its float32 effective errors and its parents' (rows r0/2.., float32; None: the root, no parent), a few rows at a
    time (memory)."""
    total = g[f"nodes/effective/{lev}"].shape[0]
    out = _array(g, f"nodes/sides/{lev}", total, "f4", chunk)
    step = 2 * max(1, SIDE_NODES // total // 2)
    for b0 in range(r0, r1, step):
        b1 = min(b0 + step, r1)
        p = None if parent is None else parent[(b0 - r0) // 2 : (b1 - r0 + 1) // 2]
        out[b0:b1, :] = side_codes(np.asarray(sides[:, b0:b1, :]), np.asarray(g[f"nodes/effective/{lev}"][b0:b1, :]), p)
