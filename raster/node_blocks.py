"""Per sub-block deviation maxima of a level's large nodes, so that an edit re-measures only what it touches.

The exact errors of a level-g node (``raster.rect_nodes._window_errors``) are maxima over the node's samples,
its borders included: of the full fan's deviation (``e``; both fans' in the combined form) and, per triangle of
the stitched fan, of the stitched fan's (``sides`` W, E, S, N). For nodes larger than ``SUB_CELLS`` cells this
module keeps those maxima per sub-block of SUB_CELLS x SUB_CELLS cells (its (SUB_CELLS + 1)² samples, borders
shared with its neighbours as the node's are), laid out per pair of representatives as rect_nodes' compact arrays
are, so a node's values are maxima over its sub-blocks: the same numbers, bit for bit.

A sample's deviations read its own height and the node's posts: rows and columns a s, a s + k, a s + s of node
a (side s = 2k; posts of the next node, which the node's last row and column read, weigh an exact zero). After
the samples of a window change, a sub-block's maxima can change only where its own samples meet the window, or
where the window holds a post row and a post column of its node (the whole node then). ``refresh`` re-measures
those sub-blocks only.

The measurement is one loop compiled by numba over the samples (``node_block_loops``, whose ``_deviations`` repeats
``hybrid.tiles.fans.fans_at``'s floating-point operations in its order, so the values are the same): as array
operations an edit's few small windows a level cost their number of NumPy calls, not their samples.
"""

from __future__ import annotations

import threading

import numpy as np

from hybrid.terrain.edits import Window

from . import rect_nodes as rn

SUB_CELLS = 32  # cells a side of a sub-block whose maxima are kept
_PARALLEL = threading.Lock()


def uses_blocks(g: int, bound: bool) -> bool:
    """Whether level g's nodes (2^(g+1) cells) keep sub-block maxima: exact levels larger than a sub-block."""
    return not bound and (2 << g) > SUB_CELLS


def block_cells(g: int) -> int:
    """Cells a side of level g's sub-blocks: SUB_CELLS, or the node itself where it is no larger."""
    return min(2 << g, SUB_CELLS)


def _measure(h: np.ndarray, g: int, R: int, side_errors: bool, rows: tuple, cols: tuple) -> np.ndarray:
    """(channels, nbr, nbc) sub-block maxima over square sample rows rows[0] .. rows[1] and columns cols[0] ..
    cols[1] (whole sub-blocks of level-g nodes, of ``block_cells(g)`` cells): e, then (``side_errors``) the
    stitched deviation's maxima over each triangle W, E, S, N of the sub-block's node."""
    B = block_cells(g)
    (p0, p1), (q0, q1) = rows, cols
    out = np.zeros((5 if side_errors else 1, (p1 - p0) // B, (q1 - q0) // B))
    from .node_block_loops import measure_blocks

    with _PARALLEL:  # numba's default thread pool runs one parallel loop at a time
        measure_blocks(h, g, R, B.bit_length() - 1, side_errors, p0, p1, q0, q1, out)
    return out


def measure(
    h: np.ndarray, ax_r: tuple, ax_c: tuple, g: int, R: int, side_errors: bool, ar: np.ndarray, ac: np.ndarray
) -> np.ndarray:
    """(channels, len(ar) * per, len(ac) * per) float64: the sub-block maxima of the level-g representatives at
    compact positions ar x ac (sorted; per = node side / ``block_cells(g)`` sub-blocks a side), one pass over
    each run of consecutive nodes."""
    s = 2 << g
    per = s // block_cells(g)
    out = np.zeros((5 if side_errors else 1, ar.size * per, ac.size * per))
    for a0, a1, i in rn._segments(ax_r[1][g][ar]):
        for b0, b1, j in rn._segments(ax_c[1][g][ac]):
            out[:, i * per : (i + a1 - a0) * per, j * per : (j + b1 - b0) * per] = _measure(
                h, g, R, side_errors, (a0 * s, a1 * s), (b0 * s, b1 * s)
            )
    return out


def _hits(ax: tuple, g: int, idx: np.ndarray, samples: int, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
    """Per level-g representative at compact positions idx along an axis: ((first, end) sub-blocks whose own
    samples meet [lo, hi), (0, 0) if none; whether the window holds one of the node's post rows)."""
    s, B = 2 << g, block_cells(g)
    nodes = ax[1][g][idx] * s
    q = np.arange(s // B)
    first = np.minimum(nodes[:, None] + q * B, samples - 1)
    last = np.minimum(nodes[:, None] + (q + 1) * B, samples - 1)
    own = (first <= hi - 1) & (last >= lo)
    ranges = np.zeros((idx.size, 2), np.int64)
    any_own = own.any(axis=1)
    ranges[any_own, 0] = own[any_own].argmax(axis=1)
    ranges[any_own, 1] = own.shape[1] - own[any_own, ::-1].argmax(axis=1)
    posts = np.minimum(nodes[:, None] + np.array([0, s // 2, s]), samples - 1)
    return ranges, ((posts >= lo) & (posts < hi)).any(axis=1)


def refresh(
    vals: np.ndarray,
    h: np.ndarray,
    ax_r: tuple,
    ax_c: tuple,
    g: int,
    R: int,
    side_errors: bool,
    mr: np.ndarray,
    mc: np.ndarray,
    win: Window,
) -> int:
    """Re-measure, in the sub-block maxima of every level-g representative (``measure``'s layout), those of the
    representatives mr x mc (compact positions whose samples meet the window of changed samples) that the window
    reaches; returns how many sub-blocks."""
    s, B = 2 << g, block_cells(g)
    per = s // B
    rows, cols = h.shape
    own_r, post_r = _hits(ax_r, g, mr, rows, win.i0, win.i1)
    own_c, post_c = _hits(ax_c, g, mc, cols, win.j0, win.j1)
    done = 0
    for x, i in enumerate(mr):
        for y, j in enumerate(mc):
            (r0, r1), (c0, c1) = ((0, per), (0, per)) if post_r[x] and post_c[y] else (own_r[x], own_c[y])
            if r1 <= r0 or c1 <= c0:
                continue
            a, b = int(ax_r[1][g][i]) * s, int(ax_c[1][g][j]) * s
            vals[:, i * per + r0 : i * per + r1, j * per + c0 : j * per + c1] = _measure(
                h, g, R, side_errors, (a + r0 * B, a + r1 * B), (b + c0 * B, b + c1 * B)
            )
            done += (r1 - r0) * (c1 - c0)
    return done


def node_values(vals: np.ndarray, g: int, ar: np.ndarray, ac: np.ndarray) -> tuple:
    """(e (nar, nac), sides (4, nar, nac) or None) of the representatives at positions ar x ac of sub-block maxima
    (``measure``'s layout): maxima over their sub-blocks."""
    per = (2 << g) // block_cells(g)
    rows = (ar[:, None] * per + np.arange(per)).ravel()
    cols = (ac[:, None] * per + np.arange(per)).ravel()
    part = vals[:, rows][:, :, cols]
    if per > 1:
        part = part.reshape(vals.shape[0], ar.size, per, ac.size, per).max(axis=(2, 4))
    return part[0], (part[1:] if part.shape[0] > 1 else None)
