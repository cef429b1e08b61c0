"""The raster strategies' node arrays over the grid's own rectangle, with the values of the padded square.

``raster.nodes.square_nodes`` runs ``raster.quadtree.error_pyramid`` over the pyramid's whole addressing square of
R = n * 2^L cells (the grid's edge samples repeated), R² samples however thin the grid: a 8 x 20000 strip asks for
32768². Tiles exist only over the grid's rectangle, and read at global level g (nodes of s = 2^(g+1) cells) the
nodes under them plus a one-node apron: a prefix of rows and columns of the level (``_extents``). This module
computes those nodes only, with the values the square gives them.

Every quantity of a level-g node (its fans' errors, side errors, saturated effective error, height range) is the
same function, per axis, of (a) the classes of the level-(g-1) nodes at 2a-1 .. 2a+2 along that axis (children and
the children's outside neighbours, which the facing side errors and the dilation read; -1 beyond the square) and
(b) for level 0, the sample rows 2a .. 2a+2 and whether the node is the square's last (where ``fans_at`` clamps).
Beyond the grid every sample row repeats the last one, so away from the grid and from the square's far edge all
nodes of a level fall into a few classes (``axis_classes``). The arrays are computed for one representative node of each
pair of row and column classes: the grid's nodes, a few beyond it and a few at the square's far edge, each from
its own window of samples (``hybrid.tiles.fans``: the same floating-point operations whatever window holds them),
so memory and time follow the grid's samples plus a few node rows and columns of padding a level.

Nodes of up to EXACT_SPAN cells get their errors measured exactly (equal bit for bit to the square's); larger
ones are bounded as the tile store bounds them (``hybrid.tiles.store_nodes``: the fan's deviation at the
children's posts plus the children's error plus 16 ulps, rounded up to float32), never below the exact value.
"""

from __future__ import annotations

import numpy as np

from hybrid.tiles.fans import (
    block2,
    cell_centre_error,
    cell_max,
    fan_deviation,
    fan_deviations,
    grow3,
    side_maxima,
    with_cell_centres,
)
from hybrid.tiles.sidecodes import side_codes_each

EXACT_SPAN = 1024  # node sides (level-0 cells) up to which errors are measured exactly
SLICE_SAMPLES = 1 << 18  # samples whose fan deviations are held at once (memory bound)
BLOCK_CELLS = 512  # cells a side of a window of samples read at once (memory bound)


def square_cells(rows: int, cols: int, n: int) -> tuple[int, int]:
    """(R, L): cells a side of the pyramid's addressing square for tiles of n cells, and its top tile level
    (as ``hybrid.tiles.pyramid.TilePyramid``)."""
    tiles0 = -(-(max(rows, cols) - 1) // n)
    L = int(np.ceil(np.log2(tiles0))) if tiles0 > 1 else 0
    return n << L, L


def _extents(samples: int, n: int, L: int, levels: int) -> list[int]:
    """Per global level: how many nodes along one axis (from index 0) the tiles over ``samples`` read."""
    top = int(np.log2(n)) - 1
    out = []
    for g in range(levels):
        far = 0
        for lev in range(max(0, g - top), min(g, L) + 1):
            tiles = max(1, -(-(samples - 1) // (n << lev)))
            far = max(far, tiles * (n >> (g - lev + 1)) + 1)
        out.append(min(far, (n << L) >> (g + 1)))
    return out


def axis_classes(samples: int, R: int, levels: int) -> tuple[list, list, list]:
    """Per global level along one axis of the square (``samples`` real samples, R cells): (maps, reps, near).
    maps[g]: node index -> index of its class's representative in reps[g] (sorted node indices, each class's
    first node); near[g] (4, reps): the compact indices at level g-1 of nodes 2a-1 .. 2a+2 of each
    representative a (-1 beyond the square)."""
    prev = np.minimum(np.arange(R + 1), samples - 1)  # sample classes: the padding repeats the last row
    maps: list[np.ndarray] = []
    reps: list[np.ndarray] = []
    near: list[np.ndarray | None] = []
    for g in range(levels):
        N = R >> (g + 1)
        a = np.arange(N)
        if g == 0:
            key = np.stack([prev[2 * a], prev[2 * a + 1], prev[2 * a + 2], (a == N - 1).astype(np.int64)])
        else:
            idx = 2 * a[None, :] + np.arange(-1, 3)[:, None]
            key = np.where((idx >= 0) & (idx < 2 * N), prev[np.clip(idx, 0, 2 * N - 1)], -1)
        _, first, cls = np.unique(key, axis=1, return_index=True, return_inverse=True)
        cls = cls.ravel()
        order = np.argsort(first)
        rank = np.empty_like(order)
        rank[order] = np.arange(order.size)
        maps.append(rank[cls])
        reps.append(first[order])
        if g:
            idx = 2 * reps[-1][None, :] + np.arange(-1, 3)[:, None]
            ok = (idx >= 0) & (idx < 2 * N)
            near.append(np.where(ok, maps[-2][np.clip(idx, 0, 2 * N - 1)], -1))
        else:
            near.append(None)
        prev = cls
    return maps, reps, near


def _segments(reps: np.ndarray) -> list[tuple[int, int, int]]:
    """Runs of consecutive node indices in sorted representatives: (first node, end node, first compact index)."""
    cut = np.flatnonzero(np.diff(reps) != 1) + 1
    starts = np.concatenate([[0], cut])
    ends = np.concatenate([cut, [reps.size]])
    return [(int(reps[i]), int(reps[j - 1]) + 1, int(i)) for i, j in zip(starts, ends)]


def _samples(h: np.ndarray, r: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Padded-square samples at rows r, columns c (clamped to the grid), float64."""
    return h[np.ix_(np.minimum(r, h.shape[0] - 1), np.minimum(c, h.shape[1] - 1))].astype(np.float64)


def _window_errors(w: np.ndarray, r0: int, c0: int, g: int, R: int, side_errors: bool):
    """(e (Nr, Nc), sides (4, Nr, Nc) or None) in metres of the level-g nodes whose samples the window w holds
    (rows r0.., columns c0.., whole nodes): the full fan's error and its stitched triangles' (``side_errors``), else
    both fans in one error; level 0's with the cell centres' terms, as ``error_pyramid``."""
    s = 2 << g
    total, width = w.shape[0] - 1, w.shape[1]
    Nr, Nc = total // s, (width - 1) // s
    S = max(2, 1 << int(np.log2(max(SLICE_SAMPLES // width, 1))))
    S = min(S, total) if S >= s else S  # whole nodes a slice, or a power-of-two part of one
    cols = np.arange(c0, c0 + width)
    e = np.zeros((Nr, Nc))
    sides = np.zeros((4, Nr, Nc)) if side_errors else None
    for i0 in range(0, total, S):
        i1 = min(i0 + S, total)
        df, ds = fan_deviations(w, r0, c0, np.arange(r0 + i0, r0 + i1 + 1), cols, g, R)
        sr, a = min(s, i1 - i0), i0 // s
        dev = df if side_errors else np.maximum(df, ds)
        part = cell_max(dev).reshape((i1 - i0) // sr, sr, Nc, s).max(axis=(1, 3))
        np.maximum(e[a : a + part.shape[0]], part, out=e[a : a + part.shape[0]])
        if sides is not None:  # side_errors
            part = side_maxima(ds, g, i0 % s if i1 - i0 < s else 0)
            np.maximum(sides[:, a : a + part.shape[1]], part, out=sides[:, a : a + part.shape[1]])
        del df, ds, dev
    if g == 0:
        if sides is not None:  # side_errors
            sides = with_cell_centres(w, sides)
        else:
            e = np.maximum(e, cell_centre_error(w))
    return e, sides


def _blocks(segments, s: int):
    """The runs of representatives cut into blocks of at most BLOCK_CELLS cells (at least one node):
    (first node, end node, first compact index)."""
    step = max(1, BLOCK_CELLS // s)
    return [(a, min(a + step, a1), i + a - a0) for a0, a1, i in segments for a in range(a0, a1, step)]


def measured_errors(h, ax_r, ax_c, g: int, R: int, side_errors: bool):
    """Level g's measured errors at every pair of representatives (compact arrays, ``_window_errors``), and for
    level 0 the nodes' height ranges (zmin, zmax; else None), one window of samples per block of them."""
    nr, nc = ax_r[1][g].size, ax_c[1][g].size
    e = np.zeros((nr, nc))
    sides = np.zeros((4, nr, nc)) if side_errors else None
    zr = (np.zeros((nr, nc)), np.zeros((nr, nc))) if g == 0 else None
    s = 2 << g
    for a0, a1, i in _blocks(_segments(ax_r[1][g]), s):
        for b0, b1, j in _blocks(_segments(ax_c[1][g]), s):
            w = _samples(h, np.arange(a0 * s, a1 * s + 1), np.arange(b0 * s, b1 * s + 1))
            at = (slice(i, i + a1 - a0), slice(j, j + b1 - b0))
            e[at], d = _window_errors(w, a0 * s, b0 * s, g, R, side_errors)
            if sides is not None:  # side_errors
                sides[(slice(None),) + at] = d
            if zr is not None:
                lo = np.minimum(np.minimum(w[:-1, :-1], w[:-1, 1:]), np.minimum(w[1:, :-1], w[1:, 1:]))
                hi = np.maximum(np.maximum(w[:-1, :-1], w[:-1, 1:]), np.maximum(w[1:, :-1], w[1:, 1:]))
                zr[0][at], zr[1][at] = block2(lo, np.min), block2(hi, np.max)
    return e, sides, zr


def post_bounds(h, ax_r, ax_c, g: int, R: int) -> np.ndarray:
    """(nr, 2, nc, 2) per child of each pair of level-g representatives: level g's fan deviation (both fans,
    metres) at the child's 3x3 posts (every 2^(g-1) samples), as the tile store's bounded levels take it."""
    nr, nc = ax_r[1][g].size, ax_c[1][g].size
    out = np.zeros((nr, 2, nc, 2))
    step = 1 << (g - 1)
    for a0, a1, i in _segments(ax_r[1][g]):
        for b0, b1, j in _segments(ax_c[1][g]):
            p, q = np.arange(4 * a0, 4 * a1 + 1), np.arange(4 * b0, 4 * b1 + 1)
            hp = _samples(h, p * step, q * step)
            dev = block2(cell_max(fan_deviation(hp, 4 * a0, 4 * b0, p, q, 1, R >> (g - 1))), np.max)
            out[i : i + a1 - a0, :, j : j + b1 - b0, :] = dev.reshape(a1 - a0, 2, b1 - b0, 2)
    return out


def _take(arr: np.ndarray, ri: np.ndarray, ci: np.ndarray) -> np.ndarray:
    """arr[..., ri, ci] over compact indices, 0 where an index is -1 (beyond the square: no neighbour)."""
    out = arr[..., np.maximum(ri, 0)[:, None], np.maximum(ci, 0)[None, :]]
    out[..., ri < 0, :] = 0.0
    out[..., ci < 0] = 0.0
    return out


def combined_level(below: dict, ax_r, ax_c, g: int, direct, beta: float, margin: float | None) -> dict:
    """Level g's compact arrays (e, eff, sides or None, zmin, zmax) from level g-1's and its own measured errors
    ``direct`` ((e, sides) exact) or, with ``margin``, its children's post deviations (a bound)."""
    nr, nc = ax_r[2][g], ax_c[2][g]  # (4, reps) level-(g-1) indices of 2a-1 .. 2a+2

    def kid(arr, d, e):
        return _take(arr, nr[d + 1], nc[e + 1])

    pairs = [(d, e) for d in (0, 1) for e in (0, 1)]
    kids = np.max([kid(below["e"], d, e) for d, e in pairs], axis=0)
    dil = np.max(
        [kid(below["eff"], d, e) for d in range(-1, 3) for e in range(-1, 3) if not (d in (-1, 2) and e in (-1, 2))],
        axis=0,
    )
    facing = 0.0
    if below["sides"] is not None:
        W, E, S, N = below["sides"]
        facing = np.max(
            [kid(E, d, -1) for d in (0, 1)]
            + [kid(W, d, 2) for d in (0, 1)]
            + [kid(N, -1, e) for e in (0, 1)]
            + [kid(S, 2, e) for e in (0, 1)],
            axis=0,
        )
    if margin is None:
        e, sides = np.maximum(np.maximum(direct[0], kids), facing), direct[1]
    else:  # a bound of both fans, so of every side too
        each = np.stack([np.stack([kid(below["e"], d, x) for x in (0, 1)], axis=-1) for d in (0, 1)], axis=1)
        e = (direct + each).max(axis=(1, 3)) + margin
        sides = None if below["sides"] is None else np.broadcast_to(e, (4,) + e.shape).copy()
        e = np.maximum(e, facing)
    return {
        "e": e,
        "eff": np.maximum(e, np.maximum(dil, facing) / beta),
        "sides": sides,
        "zmin": np.min([kid(below["zmin"], d, e) for d, e in pairs], axis=0),
        "zmax": np.max([kid(below["zmax"], d, e) for d, e in pairs], axis=0),
    }


def float32_bounded(a: np.ndarray, bound: bool) -> np.ndarray:
    """float32 of a float64 array, rounded up where it is a bound (a bound stays a bound)."""
    b = a.astype(np.float32)
    return np.where(b < a, np.nextafter(b, np.float32(np.inf)), b) if bound else b


def _output(lv: dict, parent32, ax_r, ax_c, g: int, H: int, W: int, bound: bool):
    """(effective, zlo, zhi, side codes or None) float32 of level g's nodes [0, H) x [0, W) from its compact
    arrays; ``parent32``: level g+1's compact float32 effective errors (None: the root level)."""
    mr, mc = ax_r[0][g][:H], ax_c[0][g][:W]
    eff = float32_bounded(lv["eff"], bound)
    out = [eff[np.ix_(mr, mc)]]
    rows, cols = ax_r[0][g][: H + 1], ax_c[0][g][: W + 1]  # one more node for the 3x3 boxes, where there is one
    for kind, fn in (("zmin", np.minimum), ("zmax", np.maximum)):
        out.append(grow3(lv[kind][np.ix_(rows, cols)], fn)[:H, :W].astype(np.float32))
    codes = None
    if lv["sides"] is not None:
        codes = np.empty((H, W), np.float32)
        step = max(1, SLICE_SAMPLES // max(W, 1))  # rows at once (memory: a few 4 x float64 arrays)
        for a0 in range(0, H, step):
            a = np.arange(a0, min(a0 + step, H))
            parent = None
            if parent32 is not None:
                parent = parent32[np.ix_(ax_r[0][g + 1][a // 2], ax_c[0][g + 1][np.arange(W) // 2])]
            codes[a0 : a0 + a.size] = side_codes_each(lv["sides"][:, mr[a][:, None], mc[None, :]], out[0][a], parent)
    return (*out, codes)


def rect_nodes(grid, n: int, beta: float, side_errors: bool = True):
    """(R, effective, zlo, zhi, sides) of ``raster.nodes.GlobalNodes`` for an in-memory height field and tiles of n
    cells: per global level the float32 arrays of nodes [0, H_g) x [0, W_g) of the square, every node a tile reads
    (beyond them a tile reads nothing inside the square); sides None without ``side_errors``."""
    h = np.asarray(grid.heights)
    R, L = square_cells(grid.rows, grid.cols, n)
    levels = int(np.log2(R))
    ax_r, ax_c = axis_classes(grid.rows, R, levels), axis_classes(grid.cols, R, levels)
    ext_r, ext_c = _extents(grid.rows, n, L, levels), _extents(grid.cols, n, L, levels)
    margin = 16 * np.finfo(np.float64).eps * max(abs(float(h.min())), abs(float(h.max())), 1.0)
    outs: list[tuple] = []
    prev: dict | None = None
    prev_bound = False
    for g in range(levels):
        bound = (2 << g) > EXACT_SPAN
        if g == 0:
            e, sides, (zmin, zmax) = measured_errors(h, ax_r, ax_c, 0, R, side_errors)
            lv = {"e": e, "eff": e, "sides": sides, "zmin": zmin, "zmax": zmax}
        else:
            assert prev is not None  # level g-1's, made by the step before
            if bound:
                lv = combined_level(prev, ax_r, ax_c, g, post_bounds(h, ax_r, ax_c, g, R), beta, margin)
            else:
                lv = combined_level(
                    prev, ax_r, ax_c, g, measured_errors(h, ax_r, ax_c, g, R, side_errors)[:2], beta, None
                )
        if prev is not None:
            outs.append(
                _output(
                    prev, float32_bounded(lv["eff"], bound), ax_r, ax_c, g - 1, ext_r[g - 1], ext_c[g - 1], prev_bound
                )
            )
        prev, prev_bound = lv, bound
    assert prev is not None  # R >= 2 cells, so there is a level
    outs.append(_output(prev, None, ax_r, ax_c, levels - 1, ext_r[-1], ext_c[-1], prev_bound))
    eff, zlo, zhi, codes = zip(*outs)
    return R, eff, zlo, zhi, (codes if side_errors else None)
