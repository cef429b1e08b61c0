"""Every tile place of a small pyramid in one flat table, and the tile selection computed over all of it at once.

A pyramid whose addressing square holds at most ``DENSE_MAX_TILES`` tile places at all levels together
(Puget's 1025² map in tiles of 128 cells: 85; of 16 cells: 5461) is selected here: every tile is measured in
one batch (frustum class, distance, projected error), refinement is one gather over each tile's ancestors, and
restriction and edge levels read neighbours, ancestors and children through index tables made once per
pyramid. That is a fixed handful of array operations a view, where the level-by-level selection
(``hybrid.tiles.tiletree``) pays a dozen a level and searches sorted tile codes; on a large pyramid, measuring
every tile costs more than that walk saves. Both give the same tiles, distances, errors and edge levels (a
test compares them, and each with a per-tile traversal).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.tiles.pyramid import TilePyramid

DENSE_MAX_TILES = 8192  # measured on Puget: 0.59x the level-by-level time at 1365 places, 0.83x at 5461,
# 1.28x at 21845 (tiles of 32, 16, 8 cells)
MAX_TABLE_TILES = 1 << 20  # a table asked for beyond this is refused (it would cost ~0.2 GB)
_STEPS = ((-1, 0), (1, 0), (0, -1), (0, 1))  # W, E, S, N


def square_tiles(pyramid: TilePyramid) -> int:
    """Tile places of the pyramid's addressing square, all levels together."""
    return sum(pyramid.tiles_per_side(level) ** 2 for level in range(pyramid.max_level + 1))


@dataclass(frozen=True)
class TileTable:
    """Every tile place of a pyramid (N of them), flat; index N is a sentinel (no tile, never selected).

    level, tx, ty: (N,) int64 address, and keys (N, 3) the three side by side; exists: (N,) bool, the place
    covers real terrain; boxes: (N, 7) float64 world box corners and refinement error as
    ``TilePyramid.level_table`` (zeros where no tile exists);
    chain: (N + 1, top + 1) the place itself then its ancestors coarsest last (N beyond the root);
    neighbours: (N, 4) the same level's place across the W, E, S, N edges (N off the square);
    children: (N + 1, 4) SW, SE, NW, NE children (N at level 0);
    centre: (N, 2) world x, y of each place's centre (metres); quadrant: (N, 2) int64 tx & 1, ty & 1."""

    level: np.ndarray
    tx: np.ndarray
    ty: np.ndarray
    keys: np.ndarray
    exists: np.ndarray
    boxes: np.ndarray
    chain: np.ndarray
    neighbours: np.ndarray
    children: np.ndarray
    centre: np.ndarray
    quadrant: np.ndarray


def _build(pyramid: TilePyramid) -> TileTable:
    """The table of a pyramid's tile places (made once: ``tile_table``)."""
    top = pyramid.max_level
    sides = [pyramid.tiles_per_side(level) for level in range(top + 1)]
    base = np.concatenate([[0], np.cumsum([s * s for s in sides])]).astype(np.int64)
    n = int(base[-1])
    level = np.repeat(np.arange(top + 1), [s * s for s in sides]).astype(np.int64)
    local = np.arange(n, dtype=np.int64) - base[level]
    side = np.array(sides, dtype=np.int64)[level]
    ty, tx = local // side, local % side

    def index(lv, x, y):
        """Flat index of places (lv, x, y), N where the level is outside 0..top or the place off the square."""
        lv_ok = (lv >= 0) & (lv <= top)
        s = np.array(sides, dtype=np.int64)[np.clip(lv, 0, top)]
        ok = lv_ok & (x >= 0) & (y >= 0) & (x < s) & (y < s)
        return np.where(ok, base[np.clip(lv, 0, top)] + np.where(ok, y * s + x, 0), n)

    exists = np.zeros(n, bool)
    boxes = np.empty((n, 7))
    for lv in range(top + 1):
        rows, cols = pyramid.tile_counts(lv)
        at = slice(int(base[lv]), int(base[lv + 1]))
        grid = np.zeros((sides[lv], sides[lv]), bool)
        grid[:rows, :cols] = True
        exists[at] = grid.reshape(-1)
    _fill_boxes(pyramid, boxes)
    k = np.arange(top + 1, dtype=np.int64)[None, :]
    chain = np.full((n + 1, top + 1), n, dtype=np.int64)
    chain[:n] = index(level[:, None] + k, tx[:, None] >> k, ty[:, None] >> k)
    neighbours = np.stack([index(level, tx + dx, ty + dy) for dx, dy in _STEPS], axis=1)
    children = np.full((n + 1, 4), n, dtype=np.int64)
    for c, (ox, oy) in enumerate(((0, 0), (1, 0), (0, 1), (1, 1))):
        children[:n, c] = index(level - 1, 2 * tx + ox, 2 * ty + oy)
    hf = pyramid.hf
    span = pyramid.n << level  # level-0 cells a side of each place
    centre = np.stack(
        [hf.origin[0] + (tx + 0.5) * (span * hf.spacing_x), hf.origin[1] + (ty + 0.5) * (span * hf.spacing_y)], axis=1
    )
    quadrant = np.stack([tx & 1, ty & 1], axis=1)
    return TileTable(
        level, tx, ty, np.stack([level, tx, ty], axis=1), exists, boxes, chain, neighbours, children, centre, quadrant
    )


def _fill_boxes(pyramid: TilePyramid, boxes: np.ndarray) -> None:
    """Write every tile place's row of ``boxes`` (N, 7) from the pyramid's level tables (zeros where no tile)."""
    first = 0
    for lv in range(pyramid.max_level + 1):
        side = pyramid.tiles_per_side(lv)
        rows, cols = pyramid.tile_counts(lv)
        square = np.zeros((side, side, 7))
        square[:rows, :cols] = pyramid.level_table(lv)
        boxes[first : first + side * side] = square.reshape(-1, 7)
        first += side * side


_TABLES: weakref.WeakKeyDictionary[TilePyramid, tuple[int, TileTable]] = weakref.WeakKeyDictionary()


def tile_table(pyramid: TilePyramid) -> TileTable:
    """The pyramid's table of tile places, made on first use and kept as long as the pyramid; its boxes follow
    the pyramid's bounds after an edit (``TilePyramid.edits``)."""
    hit = _TABLES.get(pyramid)
    if hit is None:
        places = square_tiles(pyramid)
        if places > MAX_TABLE_TILES:
            raise TerrabenchError(
                f"a table of every tile place of this pyramid would hold {places} places, beyond "
                f"{MAX_TABLE_TILES}; select its tiles level by level (select_tiles(dense=False))"
            )
        hit = _TABLES[pyramid] = (pyramid.edits, _build(pyramid))
    elif hit[0] != pyramid.edits:  # the bounds changed since the boxes were read: a few array copies a level
        _fill_boxes(pyramid, hit[1].boxes)
        hit = _TABLES[pyramid] = (pyramid.edits, hit[1])
    return hit[1]


def dense_selection(pyramid: TilePyramid, measure, tau: float, eye: np.ndarray):
    """The selected tiles of a view over every tile place at once, front to back: ((keys (M, 3) level, tx, ty;
    distance, projected error, class, lo, hi) arrays of the selected tiles, their edge levels (4, M) as the
    level-by-level selection's ``restrict`` returns them, and (4, M) whether a selected tile one level finer lies
    across each edge); ``eye`` is the view's eye, world metres.

    ``measure(rows)`` gives (distance, projected error, class) of world rows [lo | hi | error] of tiles
    (the level-by-level selection's formulas, so both give the same bits)."""
    t = tile_table(pyramid)
    n = len(t.level)
    d, pe, c = measure(t.boxes)
    live = t.exists & (c >= 0)
    split = np.append(live & (pe > tau) & (t.level > 0), True)  # the sentinel: "split" above the root
    selected = np.append(live & ~split[:n] & split[t.chain[:n, 1:]].all(axis=1), False)
    while True:
        idx = np.flatnonzero(selected[:n])
        cover = selected[t.chain[t.neighbours[idx]]]  # (M, 4, top + 1)
        found = cover.any(axis=2)
        first = cover.argmax(axis=2)
        cov = np.where(found, t.level[idx][:, None] + first, -1).T  # (4, M)
        far = cov >= t.level[idx][None, :] + 2
        if not far.any():
            break
        e, i = np.nonzero(far)
        parents = np.unique(t.chain[t.neighbours[idx[i], e], first[i, e]])
        selected[parents] = False  # split: their children replace them
        kids = t.children[parents].reshape(-1)
        selected[kids[kids < n][live[kids[kids < n]]]] = True
    order = _order(t, idx, eye)
    idx, cov = idx[order], cov[:, order]
    finer = (selected[t.children[t.neighbours[idx]]].any(axis=2)).T  # (4, M)
    box = t.boxes[idx]
    return (t.keys[idx], d[idx], pe[idx], c[idx], box[:, :3], box[:, 3:6]), cov, finer


def _order(t: TileTable, idx: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """Front-to-back order of places ``idx``, the key of ``_Selection.front_to_back`` summed over each place's
    chain: every place below the root adds its quadrant's rank within its parent, ranked from the eye's side."""
    n = len(t.level)
    parent = t.chain[:n, 1] if t.chain.shape[1] > 1 else np.full(n, n)  # N: the root has none
    side = np.append(eye[None, :2] >= t.centre, np.zeros((1, 2), bool), axis=0)[parent]  # (N, 2)
    rank = (t.quadrant[:, 0] != side[:, 0]).astype(np.int64) + 2 * (t.quadrant[:, 1] != side[:, 1])
    digit = np.append(np.where(parent < n, rank << (2 * t.level), 0), 0)
    return np.argsort(digit[t.chain[idx]].sum(axis=1), kind="stable")
