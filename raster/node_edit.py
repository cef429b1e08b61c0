"""The raster strategies' node arrays following an edit: the touched nodes and what they saturate, nothing else.

``raster.rect_nodes`` computes every global level's nodes from the level below (children, their outside
neighbours' effective and side errors) and its own samples, per class of node along each axis. After the samples
of a window change, a level-g node's values can change only where its own samples meet the window or where one
of the level-(g-1) nodes it reads changed; per axis that is a short run of classes, growing by about one node a
level (the saturation across tile borders and by neighbours). ``NodeEdits`` keeps rect_nodes' per-level compact
arrays (float64), recomputes those classes with rect_nodes' own combination of a level from the one below, and
rewrites the float32 arrays of ``raster.nodes.GlobalNodes`` over the nodes that read them, so they equal a full
rebuild. A level of bounded
errors (nodes beyond ``EXACT_SPAN`` cells) depends on the grid's height range through its margin: an edit that
changes that margin rebuilds everything.

Levels of nodes larger than a sub-block keep their measured errors (the fans' deviation maxima) per sub-block
(``raster.node_blocks``), so a large node re-measures only the sub-blocks the edit reaches and takes maxima over
the kept ones elsewhere; small nodes are measured again whole. The level below is handed to the combination over
the classes it reads only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hybrid.terrain.edits import Window

from . import node_blocks as nb
from . import rect_nodes as rn
from .nodes import GlobalNodes


@dataclass
class NodeEdits:
    """rect_nodes' state of one grid: per axis its classes (maps, representatives, near), per level the compact
    arrays (dicts of float64 arrays) and whether its errors are bounds; the margin the bounds were made with; per
    level of large exact nodes their sub-block maxima (``raster.node_blocks``)."""

    n: int
    beta: float
    side_errors: bool
    R: int
    ax_r: tuple
    ax_c: tuple
    levels: list = field(default_factory=list)
    bound: list = field(default_factory=list)
    margin: float = 0.0
    blocks: dict = field(default_factory=dict)
    extremes: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # max |height| per EXTREME_BLOCK²


EXTREME_BLOCK = 64
"""Samples a side of the blocks whose largest |height| is kept, so that an edit finds the grid's margin anew from
the blocks it touched and the others' maxima, not from every sample."""


def _margin_of(extremes: np.ndarray) -> float:
    """The bounded levels' margin from the grid's largest |height| (its block maxima)."""
    return 16 * np.finfo(np.float64).eps * max(float(extremes.max(initial=0.0)), 1.0)


def block_extremes(h: np.ndarray, out: np.ndarray | None = None, win: Window | None = None) -> np.ndarray:
    """Largest |height| of each EXTREME_BLOCK² block of h (rows, cols), every block or (into ``out``) the blocks
    that meet ``win``, one band of blocks at a time."""
    B = EXTREME_BLOCK
    nr, nc = -(-h.shape[0] // B), -(-h.shape[1] // B)
    if out is None:
        out, win = np.zeros((nr, nc)), Window(0, h.shape[0], 0, h.shape[1])
    assert win is not None
    c0, c1 = win.j0 // B, -(-win.j1 // B)
    for br in range(win.i0 // B, -(-win.i1 // B)):
        band = np.abs(h[br * B : (br + 1) * B, c0 * B : c1 * B])
        pad = (c1 - c0) * B - band.shape[1]
        band = np.pad(band, ((0, 0), (0, pad))) if pad else band
        out[br, c0:c1] = band.reshape(band.shape[0], c1 - c0, B).max(axis=(0, 2))
    return out


def _sub(ax: tuple, g: int, idx: np.ndarray) -> tuple[tuple, np.ndarray | None]:
    """An axis restricted at level g to the representatives at compact positions idx (sorted), its near indices
    renumbered into the level-(g-1) classes they read (returned, sorted; -1 stays -1)."""
    reps, near = list(ax[1]), list(ax[2])
    reps[g] = ax[1][g][idx]
    below = None
    if near[g] is not None:
        at = ax[2][g][:, idx]
        below = np.unique(at[at >= 0])
        near[g] = np.where(at >= 0, np.searchsorted(below, at), -1)
    return (ax[0], reps, near), below


def _below(lv: dict, rows: np.ndarray, cols: np.ndarray) -> dict:
    """A level's compact arrays at the classes rows x cols only."""
    return {k: None if v is None else v[(..., *np.ix_(rows, cols))] for k, v in lv.items()}


def _measured(st: NodeEdits, h: np.ndarray, g: int, ar: np.ndarray, ac: np.ndarray, win: Window | None) -> tuple:
    """Level g's measured errors (e, sides) at representatives ar x ac: large nodes' from their sub-block maxima,
    those the window of changed samples reaches measured again (``raster.node_blocks``); small nodes measured."""
    if g not in st.blocks:
        vals = nb.measure(h, st.ax_r, st.ax_c, g, st.R, st.side_errors, ar, ac)
        return nb.node_values(vals, g, np.arange(ar.size), np.arange(ac.size))
    if win is not None:
        mr = _affected(st.ax_r, g, h.shape[0], win.i0, win.i1, None)
        mc = _affected(st.ax_c, g, h.shape[1], win.j0, win.j1, None)
        nb.refresh(st.blocks[g], h, st.ax_r, st.ax_c, g, st.R, st.side_errors, mr, mc, win)
    return nb.node_values(st.blocks[g], g, ar, ac)


def _compute(st: NodeEdits, h: np.ndarray, g: int, ar: np.ndarray, ac: np.ndarray, win: Window | None) -> dict:
    """Level g's compact arrays at representatives (ar, ac), from the level below (already up to date)."""
    (sr, rows), (sc, cols) = _sub(st.ax_r, g, ar), _sub(st.ax_c, g, ac)
    if g == 0:
        e, sides, (zmin, zmax) = rn.measured_errors(h, sr, sc, 0, st.R, st.side_errors)
        return {"e": e, "eff": e, "sides": sides, "zmin": zmin, "zmax": zmax}
    assert rows is not None and cols is not None  # a level above 0 reads the one below
    below = _below(st.levels[g - 1], rows, cols)
    if st.bound[g]:
        return rn.combined_level(below, sr, sc, g, rn.post_bounds(h, sr, sc, g, st.R), st.beta, st.margin)
    return rn.combined_level(below, sr, sc, g, _measured(st, h, g, ar, ac, win), st.beta, None)


def node_edits(grid, n: int, beta: float, side_errors: bool = True) -> NodeEdits:
    """rect_nodes' compact state of an in-memory height field, every class of every level computed."""
    h = np.asarray(grid.heights)
    R, _ = rn.square_cells(grid.rows, grid.cols, n)
    count = int(np.log2(R))
    st = NodeEdits(
        int(n),
        float(beta),
        bool(side_errors),
        R,
        rn.axis_classes(grid.rows, R, count),
        rn.axis_classes(grid.cols, R, count),
        extremes=block_extremes(h),
    )
    st.margin = _margin_of(st.extremes)
    for g in range(count):
        st.bound.append((2 << g) > rn.EXACT_SPAN)
        ar, ac = np.arange(st.ax_r[1][g].size), np.arange(st.ax_c[1][g].size)
        if g and nb.uses_blocks(g, st.bound[g]):
            st.blocks[g] = nb.measure(h, st.ax_r, st.ax_c, g, R, st.side_errors, ar, ac)
        st.levels.append(_compute(st, h, g, ar, ac, None))
    return st


def _member(values: np.ndarray, idx: np.ndarray, size: int) -> np.ndarray:
    """Whether each of values (compact positions in [0, size), or -1) is in idx."""
    mask = np.zeros(size + 1, bool)  # the last entry: -1, never a member
    mask[idx] = True
    return mask[values]


def _affected(ax: tuple, g: int, samples: int, lo: int, hi: int, below: np.ndarray | None) -> np.ndarray:
    """Compact positions of level-g representatives along an axis whose samples meet [lo, hi) or whose
    level-(g-1) nodes (children and their outside neighbours) are in ``below``."""
    reps, s = ax[1][g], 2 << g
    first, last = np.minimum(reps * s, samples - 1), np.minimum((reps + 1) * s, samples - 1)
    hit = (first <= hi - 1) & (last >= lo)
    if below is not None and below.size:
        hit |= _member(ax[2][g], below, ax[1][g - 1].size).any(axis=0)
    return np.flatnonzero(hit)


def _node_range(ax: tuple, g: int, idx: np.ndarray, extent: int) -> tuple[int, int]:
    """[first, end) of the level-g nodes among the first ``extent`` whose class is at a compact position in idx."""
    where = np.flatnonzero(_member(ax[0][g][:extent], idx, ax[1][g].size))
    return (int(where[0]), int(where[-1]) + 1) if where.size else (0, 0)


def _rewrite(st: NodeEdits, nodes: GlobalNodes, g: int, r: tuple[int, int], c: tuple[int, int]) -> Window:
    """Rewrite nodes[r0:r1, c0:c1] of level g's float32 arrays from the compact arrays (rect_nodes._output's
    values); returns the window of the nodes whose values changed (node indices, maybe empty)."""
    (r0, r1), (c0, c1) = r, c
    lv = st.levels[g]
    H, W = nodes.effective[g].shape
    mr, mc = st.ax_r[0][g], st.ax_c[0][g]
    eff = rn.float32_bounded(lv["eff"][np.ix_(mr[r0:r1], mc[c0:c1])], st.bound[g])
    moved = nodes.effective[g][r0:r1, c0:c1] != eff
    nodes.effective[g][r0:r1, c0:c1] = eff
    gr0, gr1 = max(r0 - 1, 0), min(r1 + 1, H + 1, mr.size)  # one node more for the 3x3 boxes
    gc0, gc1 = max(c0 - 1, 0), min(c1 + 1, W + 1, mc.size)
    for arr, kind, fn in ((nodes.zlo, "zmin", np.minimum), (nodes.zhi, "zmax", np.maximum)):
        grown = rn.grow3(lv[kind][np.ix_(mr[gr0:gr1], mc[gc0:gc1])], fn)
        new = grown[r0 - gr0 : r1 - gr0, c0 - gc0 : c1 - gc0].astype(np.float32)
        moved |= arr[g][r0:r1, c0:c1] != new
        arr[g][r0:r1, c0:c1] = new
    if nodes.sides is not None and lv["sides"] is not None:
        parent = None
        if g + 1 < len(st.levels):
            up = st.levels[g + 1]["eff"]
            parent = rn.float32_bounded(
                up[np.ix_(st.ax_r[0][g + 1][np.arange(r0, r1) // 2], st.ax_c[0][g + 1][np.arange(c0, c1) // 2])],
                st.bound[g + 1],
            )
        sides = lv["sides"][:, mr[r0:r1][:, None], mc[None, c0:c1]]
        codes = rn.side_codes_each(sides, eff, parent)
        moved |= nodes.sides[g][r0:r1, c0:c1] != codes
        nodes.sides[g][r0:r1, c0:c1] = codes
    rows, cols = np.flatnonzero(moved.any(axis=1)), np.flatnonzero(moved.any(axis=0))
    if not rows.size:
        return Window(0, 0, 0, 0)
    return Window(r0 + int(rows[0]), r0 + int(rows[-1]) + 1, c0 + int(cols[0]), c0 + int(cols[-1]) + 1)


def update_nodes(st: NodeEdits, nodes: GlobalNodes, grid, win: Window) -> list[Window]:
    """Bring the compact state and the node arrays up to date after the samples of ``win`` changed in grid's
    heights; returns per level the window of nodes whose values changed (rows and columns of node indices, maybe
    empty)."""
    h = np.asarray(grid.heights)
    margin = _margin_of(block_extremes(h, st.extremes, win))
    if margin != st.margin and any(st.bound):  # the bounded levels' margin moved: rebuild all
        vars(st).update(vars(node_edits(grid, st.n, st.beta, st.side_errors)))
        win = Window(0, grid.rows, 0, grid.cols)
    st.margin = margin
    changed, below_r, below_c = [], None, None
    for g in range(len(st.levels)):
        ar = _affected(st.ax_r, g, grid.rows, win.i0, win.i1, below_r)
        ac = _affected(st.ax_c, g, grid.cols, win.j0, win.j1, below_c)
        if ar.size and ac.size:
            part = _compute(st, h, g, ar, ac, win)
            for k, v in part.items():
                if v is not None:
                    st.levels[g][k][(..., *np.ix_(ar, ac))] = v
        changed.append((ar, ac))
        below_r, below_c = ar, ac
    return _rewrite_all(st, nodes, changed)


def _rewrite_all(st: NodeEdits, nodes: GlobalNodes, changed: list) -> list[Window]:
    """Rewrite every level's nodes whose values read changed classes: their own, their 3x3 box neighbours', and
    (side codes) their parents'; per level the window of the nodes whose values changed."""
    out = []
    for g, (ar, ac) in enumerate(changed):
        H, W = nodes.effective[g].shape
        r, c = _node_range(st.ax_r, g, ar, H), _node_range(st.ax_c, g, ac, W)
        if r[1] > r[0] and c[1] > c[0]:
            r, c = (max(r[0] - 1, 0), min(r[1] + 1, H)), (max(c[0] - 1, 0), min(c[1] + 1, W))
        if g + 1 < len(changed):  # children of changed parents: their side codes
            pr, pc = (
                _node_range(st.ax_r, g + 1, changed[g + 1][0], (H + 1) // 2),
                _node_range(st.ax_c, g + 1, changed[g + 1][1], (W + 1) // 2),
            )
            if pr[1] > pr[0] and pc[1] > pc[0]:
                pr, pc = (2 * pr[0], min(2 * pr[1], H)), (2 * pc[0], min(2 * pc[1], W))
                r = (min(r[0], pr[0]), max(r[1], pr[1])) if r[1] > r[0] else pr
                c = (min(c[0], pc[0]), max(c[1], pc[1])) if c[1] > c[0] else pc
        out.append(_rewrite(st, nodes, g, r, c) if r[1] > r[0] and c[1] > c[0] else Window(0, 0, 0, 0))
    return out
