"""The raster strategies' node arrays of a tile store, built out of core (``prepare_store`` calls ``build_nodes``).

They are the arrays ``raster.nodes.GlobalNodes`` holds in its combined form (``global_nodes(side_errors=False)``:
one error over a node's full and stitched fans, no side codes; an in-memory terrain's split on the full fan's
error with side codes, ``raster.quadtree``), over the same padded square of R = N * 2^L cells (the
grid's edge samples repeated): per global level g (nodes of 2^(g+1) level-0 cells, (R >> (g+1))² of them)
``nodes/effective/<g>`` (saturated effective error, metres), ``nodes/zlo/<g>`` and ``nodes/zhi/<g>`` (height range
of the node's box, its square grown by its side, metres relative to the origin z), float32, chunked.

How, band by band:
- Direct errors, levels whose nodes span at most NODE_EXACT_SPAN cells: blocks of that many cells of the padded
  square are read from level 0 (clamped at the grid's edges) and every fan deviation is measured at every
  sample (``hybrid.tiles.fans``: the same floating-point operations as over the whole square), so these errors
  are exactly those of ``global_nodes``.
- Larger nodes are bounded, not measured: for x in child C of node P, |F_P(x) - h(x)| <= |F_P(x) - F_C(x)| +
  |F_C(x) - h(x)|. C's full fan refines both of P's fans on C (its eight triangles are cut by C's diagonals
  and midlines, and P's fans are linear on each of them), so |F_P - F_C| peaks at C's 3x3 posts, where F_C is
  the samples: the bound is P's fan deviation at the level-(g-1) posts plus the child's error (exact or bound),
  plus 16 ulps of the largest height for float64 rounding, rounded up to float32. It is never below the exact
  value (tested), so a node never splits later than it should; it may split earlier. These levels hold at most
  (R / 2048)² nodes, so each is computed whole, from the posts of the stored level nearest below.
- Then per level, from the level below: errors made monotone, effective errors saturated (``dilate4``, 1/beta),
  height ranges min/max of the children, boxes the 3x3 range (``grow3``), each band reading its rows plus one
  node of apron. Intermediate float64 arrays live in ``nodes/tmp`` until the last level is written.

Progress is recorded after every band (attribute ``progress``), so an interrupted build resumes; the store's
``nodes`` attribute (beta, levels, square, exact span) is written when all levels are.
"""
from __future__ import annotations

import numpy as np

from .fans import block2, cell_max, dilate4, fan_deviation, grow3

NODE_EXACT_SPAN = 1024          # node sides (level-0 cells) up to which node errors are measured exactly
SLICE_ROWS = 128                # sample rows measured at once inside a block (memory bound)
NODE_BAND = 1 << 20             # nodes per band of a level's pass (memory bound)
CHUNK = 512                     # chunk side of the build's working arrays (nodes)
MIN_CHUNK = 8                   # smallest chunk side of the final node arrays (nodes)


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
    return out


def _window(lv0, rows: int, cols: int, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    """Samples rows r0..r1-1, columns c0..c1-1 of the padded square (float64), read from level 0 clamped."""
    ri, ci = np.minimum(np.arange(r0, r1), rows - 1), np.minimum(np.arange(c0, c1), cols - 1)
    a0, c_0 = int(ri[0]), int(ci[0])
    w = np.asarray(lv0[a0:int(ri[-1]) + 1, c_0:int(ci[-1]) + 1], dtype=np.float64)
    return w[np.ix_(ri - a0, ci - c_0)]


def _array(g, name: str, total: int, dtype: str, chunk: int = CHUNK):
    if name in g:
        return g[name]
    c = min(total, chunk)
    return g.create_array(name, shape=(total, total), chunks=(c, c), dtype=dtype, fill_value=np.nan)


def tile_chunk(n: int, level: int) -> int:
    """Chunk side (nodes) of global node level ``level`` in a store of n-cell tiles: the nodes a level-0 tile
    has there (at least MIN_CHUNK), so a tile's window and its one-node apron read a few small chunks."""
    return max(MIN_CHUNK, n >> (level + 1))


def _direct_band(lv0, rows, cols, R, B, gx, br) -> tuple[list, np.ndarray, np.ndarray]:
    """One band of B cell rows: direct errors of every exact level ((B / s) x (R / s) per level) and level 0's
    node height ranges."""
    r0 = br * B
    direct = [np.zeros((B >> (g + 1), R >> (g + 1))) for g in range(gx + 1)]
    zmin = np.empty((B // 2, R // 2), np.float32)
    zmax = np.empty((B // 2, R // 2), np.float32)
    S = min(SLICE_ROWS, B)
    for c0 in range(0, R, B):
        w = _window(lv0, rows, cols, r0, r0 + B + 1, c0, c0 + B + 1)
        cols_idx = np.arange(c0, c0 + B + 1)
        cmin = np.minimum(np.minimum(w[:-1, :-1], w[:-1, 1:]), np.minimum(w[1:, :-1], w[1:, 1:]))
        cmax = np.maximum(np.maximum(w[:-1, :-1], w[:-1, 1:]), np.maximum(w[1:, :-1], w[1:, 1:]))
        zmin[:, c0 // 2:(c0 + B) // 2] = block2(cmin, np.min)
        zmax[:, c0 // 2:(c0 + B) // 2] = block2(cmax, np.max)
        del cmin, cmax
        for g in range(gx + 1):
            s = 2 << g
            out = direct[g][:, c0 // s:(c0 + B) // s]
            for i0 in range(0, B, S):
                rows_idx = np.arange(r0 + i0, r0 + i0 + S + 1)
                dcell = cell_max(fan_deviation(w, r0, c0, rows_idx, cols_idx, g, R))
                sr = min(s, S)
                part = dcell.reshape(S // sr, sr, B // s, s).max(axis=(1, 3))
                a = i0 // s
                np.maximum(out[a:a + part.shape[0]], part, out=out[a:a + part.shape[0]])
    return direct, zmin, zmax


def _bound(levels_of, R: int, L: int, lev: int, kids_err: np.ndarray, margin: float) -> np.ndarray:
    """Upper bound of level ``lev``'s monotone errors (metres, float64) from the level-(lev-1) posts, read from
    the stored level ``levels_of(l)`` nearest below (every 2^l-th sample, the last row and column kept)."""
    l = min(lev - 1, L)
    arr = np.asarray(levels_of(l)[:, :], dtype=np.float64)
    P = (R >> (lev - 1)) + 1
    p = np.arange(P)
    q = p << (lev - 1 - l)
    H = arr[np.ix_(np.minimum(q, arr.shape[0] - 1), np.minimum(q, arr.shape[1] - 1))]
    post = block2(cell_max(fan_deviation(H, 0, 0, p, p, 1, P - 1)), np.max)          # per child: its 3x3 posts
    return block2(post + kids_err, np.max) + margin


def build_nodes(g, rows: int, cols: int, n: int, max_level: int, beta: float, mark) -> None:
    """Write the node arrays of a store group ``g`` whose levels are written; ``mark(key, count, what)`` records
    a band's progress (and may raise KeyboardInterrupt)."""
    R, levels = node_square(n, max_level)
    B, gx = _plan(R)
    progress = lambda key: int(dict(g.attrs["progress"]).get(key, 0))  # noqa: E731
    lv0 = g["levels/0"]
    hr = g.attrs["height_range"]
    margin = 16 * np.finfo(np.float64).eps * max(abs(float(hr[0])), abs(float(hr[1])), 1.0)
    tmp = lambda kind, lev: f"nodes/tmp/{kind}/{lev}"  # noqa: E731
    for br in range(progress("nodes:direct"), R // B):
        direct, zmin, zmax = _direct_band(lv0, rows, cols, R, B, gx, br)
        for lev, d in enumerate(direct):
            _array(g, tmp("direct", lev), R >> (lev + 1), "f8")[br * d.shape[0]:(br + 1) * d.shape[0], :] = d
        for kind, z in (("zmin", zmin), ("zmax", zmax)):
            _array(g, tmp(kind, 0), R // 2, "f4")[br * (B // 2):(br + 1) * (B // 2), :] = z
        mark("nodes:direct", br + 1, f"node errors, band {br + 1}")
    for lev in range(levels):
        total = R >> (lev + 1)
        exact = lev <= gx
        hb = _band_rows(total, exact)
        starts = list(range(0, total, hb))
        key = f"nodes:{lev}"
        done = progress(key)
        if done >= 2 * len(starts):
            continue
        arr = {k: _array(g, tmp(k, lev), total, "f4" if k.startswith("z") else "f8")
               for k in ("error", "eff", "zmin", "zmax")}
        below = {k: g[tmp(k, lev - 1)] for k in ("error", "eff", "zmin", "zmax")} if lev else None
        for i, a0 in enumerate(starts):                       # pass 1: errors, effective errors, ranges
            if i < done:
                continue
            a1 = min(a0 + hb, total)
            if lev == 0:
                e = np.asarray(g[tmp("direct", 0)][a0:a1, :])
                eff = e
            else:
                kids = np.asarray(below["error"][2 * a0:2 * a1, :])
                if exact:
                    e = np.maximum(np.asarray(g[tmp("direct", lev)][a0:a1, :]), block2(kids, np.max))
                else:
                    e = _bound(lambda l: g[f"levels/{l}"], R, max_level, lev, kids, margin)
                lo, hi = max(2 * a0 - 1, 0), min(2 * a1 + 1, 2 * total)
                d = dilate4(np.asarray(below["eff"][lo:hi, :]))[2 * a0 - lo:2 * a1 - lo]
                eff = np.maximum(e, block2(d, np.max) / beta)
                arr["zmin"][a0:a1, :] = block2(np.asarray(below["zmin"][2 * a0:2 * a1, :]), np.min)
                arr["zmax"][a0:a1, :] = block2(np.asarray(below["zmax"][2 * a0:2 * a1, :]), np.max)
            if lev == 0:
                arr["zmin"][a0:a1, :] = np.asarray(g[tmp("zmin", 0)][a0:a1, :])
                arr["zmax"][a0:a1, :] = np.asarray(g[tmp("zmax", 0)][a0:a1, :])
            arr["error"][a0:a1, :] = e
            arr["eff"][a0:a1, :] = eff
            mark(key, i + 1, f"node level {lev}, band {i + 1}")
        final = {k: _array(g, f"nodes/{k}/{lev}", total, "f4", tile_chunk(n, lev)) for k in ("effective", "zlo", "zhi")}
        for i, a0 in enumerate(starts):                       # pass 2: float32 errors, 3x3 box ranges
            if len(starts) + i < done:
                continue
            a1 = min(a0 + hb, total)
            e64 = np.asarray(arr["eff"][a0:a1, :])
            e32 = e64.astype(np.float32)
            if not exact:                                     # a bound stays a bound in float32
                e32 = np.where(e32 < e64, np.nextafter(e32, np.float32(np.inf)), e32)
            final["effective"][a0:a1, :] = e32
            lo, hi = max(a0 - 1, 0), min(a1 + 1, total)
            for kind, src, fn in (("zlo", "zmin", np.minimum), ("zhi", "zmax", np.maximum)):
                # the slab's own edges repeat only where they are the square's; other rows are the apron
                final[kind][a0:a1, :] = grow3(np.asarray(arr[src][lo:hi, :]), fn)[a0 - lo:a1 - lo]
            mark(key, len(starts) + i + 1, f"node boxes {lev}, band {i + 1}")
    g.attrs.update({"nodes": {"beta": float(beta), "levels": levels, "square": R,
                              "exact_span": B}})
    if "nodes/tmp" in g:
        del g["nodes/tmp"]
