"""Per-view tile selection: frustum culling, screen-space error refinement, restriction, front-to-back order.

A tile is refined while its projected geometric error exceeds tau pixels (default 2/3, Dick et al. §4):
``error_m * K / d`` with K = viewport height / (2 tan(fov/2)) and d the distance from the eye to the
nearest point of the tile's AABB. Selected tiles are then made restricted (edge neighbours differ by at
most one level) by splitting coarse tiles, and listed front to back by a quadtree traversal that visits
the child quadrant on the eye's side first and the opposite one last, which is a visibility order for
height-field columns.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.camera.view import View
from hybrid.errors import check_positive
from hybrid.tiles.pyramid import EDGE_E, EDGE_N, EDGE_S, EDGE_W, TileKey, TilePyramid

DEFAULT_TAU = 2.0 / 3.0
NO_NEIGHBOUR = 9
_EDGES = ((EDGE_W, -1, 0), (EDGE_E, 1, 0), (EDGE_S, 0, -1), (EDGE_N, 0, 1))


@dataclass(frozen=True)
class SelectedTile:
    """A tile chosen for a view, with what the renderers and the cost model need to know about it.

    distance: metres from the eye to the nearest point of the AABB (0 if the eye is inside it).
    projected_error: the tile's geometric error in pixels at that distance.
    coarser_edges: bit mask of edges (EDGE_W/E/S/N) whose neighbour is one level coarser (stitch there).
    inside: True if the AABB lies wholly inside the frustum (no finer culling needed).
    edge_deltas: per edge W, E, S, N, the level of the selected tile across it minus this tile's level
      (-1, 0 or 1; NO_NEIGHBOUR where no selected tile touches that edge).
    """

    key: TileKey
    distance: float
    projected_error: float
    coarser_edges: int
    inside: bool
    edge_deltas: tuple = (9, 9, 9, 9)

    @property
    def level(self) -> int:
        """Pyramid level of the tile."""
        return self.key.level


def aabb_distance(eye: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Euclidean distance (metres) from a point to an axis-aligned box; 0 inside."""
    d = np.maximum(np.maximum(lo - eye, eye - hi), 0.0)
    return float(np.linalg.norm(d))


def classify_aabb(planes: np.ndarray, lo_rel: np.ndarray, hi_rel: np.ndarray) -> int:
    """-1 if the eye-relative box is outside the frustum, 1 if wholly inside, 0 if it crosses a plane."""
    n = planes[:, :3]
    pos = np.where(n >= 0, hi_rel, lo_rel)   # corner farthest along each normal
    neg = np.where(n >= 0, lo_rel, hi_rel)
    if np.any(np.einsum("ij,ij->i", n, pos) + planes[:, 3] < 0):
        return -1
    if np.all(np.einsum("ij,ij->i", n, neg) + planes[:, 3] >= 0):
        return 1
    return 0


def _covering(selected: dict, key: TileKey, max_level: int):
    """The selected tile at key's level or coarser that contains key's area, or None."""
    l, x, y = key.level, key.tx, key.ty
    while l <= max_level:
        k = TileKey(l, x, y)
        if k in selected:
            return k
        l, x, y = l + 1, x // 2, y // 2
    return None


def select_tiles(pyramid: TilePyramid, view: View, tau: float = DEFAULT_TAU) -> list[SelectedTile]:
    """Tiles to draw for a view with screen-space error <= tau pixels: restricted, culled, front to back."""
    tau = check_positive("tau (pixels)", tau)
    planes = view.frustum_planes_rel()
    eye = view.eye
    K = view.pixels_per_radian
    info: dict[TileKey, tuple[float, float, int]] = {}

    def classify(key):
        if key not in info:
            lo, hi = pyramid.aabb(key)
            c = classify_aabb(planes, lo - eye, hi - eye)
            d = aabb_distance(eye, lo, hi)
            pe = pyramid.error(key) * K / d if d > 0 else (np.inf if pyramid.error(key) > 0 else 0.0)
            info[key] = (d, pe, c)
        return info[key]

    def live_children(key):
        return [c for c in key.children() if pyramid.exists(c) and classify(c)[2] >= 0]

    selected: dict[TileKey, bool] = {}
    stack = [pyramid.root()] if classify(pyramid.root())[2] >= 0 else []
    while stack:
        key = stack.pop()
        d, pe, c = classify(key)
        if key.level > 0 and pe > tau:
            stack.extend(live_children(key))
        else:
            selected[key] = True

    # restriction: split any tile that has an edge neighbour two or more levels finer
    changed = True
    while changed:
        changed = False
        for key in list(selected):
            if key not in selected:
                continue
            t = pyramid.tiles_per_side(key.level)
            for _, dx, dy in _EDGES:
                nx, ny = key.tx + dx, key.ty + dy
                if not (0 <= nx < t and 0 <= ny < t):
                    continue
                cov = _covering(selected, TileKey(key.level, nx, ny), pyramid.max_level)
                if cov is not None and cov.level >= key.level + 2:
                    del selected[cov]
                    for ch in live_children(cov):
                        selected[ch] = True
                    changed = True

    # per edge: the selected neighbour's level minus this tile's (-1, 0, 1), NO_NEIGHBOUR where none is drawn
    result_edges, deltas = {}, {}
    for key in selected:
        t = pyramid.tiles_per_side(key.level)
        mask, d = 0, []
        for bit, dx, dy in _EDGES:
            nx, ny = key.tx + dx, key.ty + dy
            delta = NO_NEIGHBOUR
            if 0 <= nx < t and 0 <= ny < t:
                nb = TileKey(key.level, nx, ny)
                cov = _covering(selected, nb, pyramid.max_level)
                if cov is not None:
                    delta = cov.level - key.level
                elif key.level > 0 and any(c in selected for c in nb.children()):
                    delta = -1
            if delta == 1:
                mask |= bit
            d.append(delta)
        result_edges[key], deltas[key] = mask, tuple(d)

    # front-to-back order by quadtree traversal
    needed = set()
    for key in selected:
        k = key
        while k.level < pyramid.max_level:
            k = k.parent()
            if k in needed:
                break
            needed.add(k)
    order: list[TileKey] = []

    def visit(key):
        if key in selected:
            order.append(key)
            return
        if key not in needed:
            return
        x0, y0, x1, y1 = pyramid.clip(key)
        cells = pyramid.n << key.level
        span_x, span_y = cells * pyramid.hf.spacing_x, cells * pyramid.hf.spacing_y
        mx = pyramid.hf.origin[0] + key.tx * span_x + span_x / 2
        my = pyramid.hf.origin[1] + key.ty * span_y + span_y / 2
        sx, sy = int(eye[0] >= mx), int(eye[1] >= my)
        ch = key.children()  # SW, SE, NW, NE -> index = x + 2y
        for qx, qy in ((sx, sy), (1 - sx, sy), (sx, 1 - sy), (1 - sx, 1 - sy)):
            visit(ch[qx + 2 * qy])

    visit(pyramid.root())
    return [SelectedTile(k, info[k][0], info[k][1], result_edges[k], info[k][2] == 1, deltas[k]) for k in order]


def edge_neighbours(keys: set, key: TileKey, dx: int, dy: int, max_level: int) -> list[TileKey]:
    """Tiles of a selection that touch ``key``'s edge in direction (dx, dy): same level, coarser or finer."""
    nx, ny = key.tx + dx, key.ty + dy
    if nx < 0 or ny < 0:
        return []
    cov = _covering(keys, TileKey(key.level, nx, ny), max_level)
    if cov is not None:
        return [cov]
    out, frontier = [], [TileKey(key.level, nx, ny)]
    while frontier and frontier[0].level > 0:
        nxt = []
        for k in frontier:
            for c in k.children():
                # keep the children on the side that faces key
                if (dx == 1 and c.tx % 2 == 0) or (dx == -1 and c.tx % 2 == 1) or \
                        (dy == 1 and c.ty % 2 == 0) or (dy == -1 and c.ty % 2 == 1):
                    (out if c in keys else nxt).append(c)
        frontier = nxt
    return out
