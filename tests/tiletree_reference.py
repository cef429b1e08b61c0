"""The tile selection as a plain per-tile traversal (one Python step per tile): the independent reference that
hybrid.tiles.tiletree's vectorised select_tiles is checked against in tests."""

import math

import numpy as np

from hybrid.errors import check_positive
from hybrid.tiles.pyramid import EDGE_E, EDGE_N, EDGE_S, EDGE_W, TileKey
from hybrid.tiles.tiletree import NO_NEIGHBOUR, SelectedTile
from hybrid.tiles.tiletree import covering_tile as _covering

_EDGES = ((EDGE_W, -1, 0), (EDGE_E, 1, 0), (EDGE_S, 0, -1), (EDGE_N, 0, 1))


def aabb_distance(eye: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Euclidean distance (metres) from a point to an axis-aligned box; 0 inside."""
    d = [float(v) for v in np.maximum(np.maximum(lo - eye, eye - hi), 0.0)]
    return math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])


def classify_aabb(planes: np.ndarray, lo_rel: np.ndarray, hi_rel: np.ndarray) -> int:
    """-1 if the eye-relative box is outside the frustum, 1 if wholly inside, 0 if it crosses a plane."""
    n = planes[:, :3]
    pos = np.where(n >= 0, hi_rel, lo_rel)  # corner farthest along each normal
    neg = np.where(n >= 0, lo_rel, hi_rel)
    if np.any(np.einsum("ij,ij->i", n, pos) + planes[:, 3] < 0):
        return -1
    if np.all(np.einsum("ij,ij->i", n, neg) + planes[:, 3] >= 0):
        return 1
    return 0


def select_tiles_by_traversal(pyramid, view, tau: float = 2 / 3) -> list[SelectedTile]:
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
            err = pyramid.error(key) + pyramid.quantization_error(key)  # geometric + 16-bit heights
            pe = err * K / d if d > 0 else (np.inf if err > 0 else 0.0)
            info[key] = (d, pe, c)
        return info[key]

    def live_children(key):
        return [c for c in key.children() if pyramid.exists(c) and classify(c)[2] >= 0]

    selected: dict[TileKey, bool] = {}
    stack = [pyramid.root()] if classify(pyramid.root())[2] >= 0 else []
    while stack:
        key = stack.pop()
        d, pe, _c = classify(key)
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
        _x0, _y0, _x1, _y1 = pyramid.clip(key)
        span_x = (pyramid.n << key.level) * pyramid.hf.spacing_x
        span_y = (pyramid.n << key.level) * pyramid.hf.spacing_y
        mx = pyramid.hf.origin[0] + key.tx * span_x + span_x / 2
        my = pyramid.hf.origin[1] + key.ty * span_y + span_y / 2
        sx, sy = int(eye[0] >= mx), int(eye[1] >= my)
        ch = key.children()  # SW, SE, NW, NE -> index = x + 2y
        for qx, qy in ((sx, sy), (1 - sx, sy), (sx, 1 - sy), (1 - sx, 1 - sy)):
            visit(ch[qx + 2 * qy])

    visit(pyramid.root())
    return [SelectedTile(k, info[k][0], info[k][1], result_edges[k], info[k][2] == 1, deltas[k]) for k in order]
