"""Screen footprints of many world boxes at once: near-plane cut, convex hull, viewport clip (pixels, numpy).

The batched counterpart of ``hybrid.cost.features.footprint_pixels``: the same points (box corners in front
of the near plane and box edges' crossings of it, projected and rounded to 1e-6 px), the same convex hull
and the same Sutherland-Hodgman clip, with one row per box and padded slots instead of Python lists.
"""
from __future__ import annotations

import numpy as np

from hybrid.camera.view import View

# box corner index = 4 * (x is hi) + 2 * (y is hi) + (z is hi), as in features.footprint_pixels
_CORNER_BITS = np.array([[(c >> 2) & 1, (c >> 1) & 1, c & 1] for c in range(8)], dtype=bool)
_EDGE_A, _EDGE_B = np.array([(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]).T
# a point closer than this times the coordinate scale to a hull edge's line counts as on it (float noise)
_COLLINEAR = 1e-12


def box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(B, 8, 3) world corners of B boxes given their (B, 3) min and max corners, in footprint order."""
    return np.where(_CORNER_BITS[None], hi[:, None, :], lo[:, None, :])


def screen_points(view: View, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Projected vertices of boxes cut at the near plane: (B, 20, 2) pixel positions and a (B, 20) validity mask.

    Slots 0-7 are the corners in front of the near plane, slots 8-19 the crossings of the 12 box edges
    with it; positions are rounded to 1e-6 px so that coincident corners merge.
    """
    b = corners.shape[0]
    rel = ((corners - view.eye).reshape(-1, 3) @ view.rotation().T).reshape(b, 8, 3)   # eye space, looks down -z
    depth = -rel[:, :, 2]
    near = view.near * (1 + 1e-9)
    da, db = depth[:, _EDGE_A], depth[:, _EDGE_B]
    crossing = (da - near) * (db - near) < 0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(crossing, (near - da) / np.where(crossing, db - da, 1.0), 0.0)
    ra, rb = rel[:, _EDGE_A], rel[:, _EDGE_B]
    pts = np.concatenate([rel, ra + t[..., None] * (rb - ra)], axis=1)
    valid = np.concatenate([depth >= near, crossing], axis=1)
    pts = np.where(valid[..., None], pts, np.array([0.0, 0.0, -1.0]))     # a harmless point in unused slots
    tan = view.tan_half_fov
    x = (pts[..., 0] / -pts[..., 2]) / (tan * view.aspect)
    y = (pts[..., 1] / -pts[..., 2]) / tan
    screen = np.stack([(x + 1) * 0.5 * view.width, (1 - y) * 0.5 * view.height], axis=-1)
    return np.round(screen, 6), valid


def _pack(pts: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kept points moved to the front of each row in order, the rest filled with the row's last kept point.

    Returns (B, m, 2) points (m = the largest count of any row, at least 1) and the (B,) counts; a repeated
    last vertex adds only zero-length edges to a polygon, so padded rows keep their area.
    """
    order = np.argsort(~keep, axis=1, kind="stable")
    count = keep.sum(axis=1)
    m = max(int(count.max(initial=0)), 1)
    slots = np.minimum(np.arange(m)[None, :], np.maximum(count - 1, 0)[:, None])
    idx = np.take_along_axis(order, slots, axis=1)
    return np.take_along_axis(pts, idx[..., None], axis=1), count


def hull_polygons(pts: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Convex hulls of each row's valid points, counter-clockwise: (B, m, 2) padded vertices and (B,) counts.

    Duplicates are merged; points on a hull edge between its ends are not vertices. A hull of fewer than 3
    vertices (all points on one line) has no area.
    """
    pts, count = _pack(pts, valid)
    k = pts.shape[1]
    slot = np.arange(k)
    live = slot[None, :] < count[:, None]
    same = np.all(pts[:, :, None, :] == pts[:, None, :, :], axis=-1) & (slot[:, None] < slot[None, :])[None]
    live &= ~np.any(same & live[:, :, None], axis=1)                 # keep the first of equal points
    # edge i -> j is a hull edge when every other point lies left of it, or on it between i and j
    e = pts[:, None, :, :] - pts[:, :, None, :]                      # (B, i, j, 2): j - i
    f = pts[:, None, None, :, :] - pts[:, :, None, None, :]          # (B, i, 1, k, 2): k - i
    cross = e[:, :, :, None, 0] * f[..., 1] - e[:, :, :, None, 1] * f[..., 0]
    scale = np.maximum(np.abs(np.where(live[..., None], pts, 0.0)).max(axis=(1, 2)), 1.0)[:, None, None, None]
    tol = _COLLINEAR * scale * (np.abs(e[:, :, :, None, :]).sum(-1) + np.abs(f).sum(-1))
    along = e[:, :, :, None, 0] * f[..., 0] + e[:, :, :, None, 1] * f[..., 1]
    length2 = (e[..., 0] ** 2 + e[..., 1] ** 2)[..., None]
    ok = (cross > tol) | ((np.abs(cross) <= tol) & (along >= 0) & (along <= length2)) | ~live[:, None, None, :]
    edge = np.all(ok, axis=-1) & live[:, :, None] & live[:, None, :] & (length2[..., 0] > 0)
    vertex = np.any(edge, axis=2)
    nv = vertex.sum(axis=1)
    centre = np.where(vertex[..., None], pts, 0.0).sum(axis=1) / np.maximum(nv, 1)[:, None]
    angle = np.arctan2(pts[..., 1] - centre[:, None, 1], pts[..., 0] - centre[:, None, 0])
    order = np.argsort(np.where(vertex, angle, np.inf), axis=1, kind="stable")
    poly = np.take_along_axis(pts, order[..., None], axis=1)
    ordered = np.take_along_axis(vertex, order, axis=1)
    poly, _ = _pack(poly, ordered)
    return poly, np.where(nv >= 3, nv, 0)


def _silhouettes() -> np.ndarray:
    """(64, 6) corner indices of a box's outline in cyclic order, by the eye's region code (see ``region_codes``).

    Seen from outside a box, its projection's outline is the cycle of edges between faces turned to the eye
    and faces turned away, fixed by the eye's region (Schmalstieg and Tobler 1999): worked out here once from
    one eye inside each region; 4-vertex outlines repeat their last corner. Code 0 (eye inside) has none.
    """
    table = np.zeros((64, 6), dtype=np.int64)
    corners = _CORNER_BITS.astype(np.float64)
    for sides in np.ndindex(3, 3, 3):
        eye = np.array([(-2.0, 0.5, 3.0)[s] for s in sides])
        code = int(region_codes(eye[None], np.zeros((1, 3)), np.ones((1, 3)))[0])
        if code == 0:
            continue
        f = 0.5 - eye
        f /= np.linalg.norm(f)
        a = np.cross(f, [0.3, 0.5, 0.7])
        a /= np.linalg.norm(a)
        b = np.cross(f, a)
        d = corners - eye
        uv = np.stack([d @ a, d @ b], axis=1) / (d @ f)[:, None]      # a perspective picture of the corners
        ang = np.arctan2(*(uv - uv.mean(axis=0)).T[::-1])
        outline = [c for c in np.argsort(ang) if not _inside_others(uv, c)]
        table[code] = (outline + outline[-1:] * 6)[:6]
    return table


def _inside_others(uv: np.ndarray, c: int) -> bool:
    """Whether point c lies inside the convex hull of the other points (a strict test; points in general position)."""
    others = np.delete(uv, c, axis=0)
    ang = np.sort(np.arctan2(*(others - uv[c]).T[::-1]))
    gaps = np.diff(np.concatenate([ang, ang[:1] + 2 * np.pi]))    # angular gaps between the others, seen from c
    return bool(gaps.max() < np.pi)


def region_codes(eye: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(B,) 6-bit codes of where eyes (B, 3) lie against boxes: bits x<lo, x>hi, y<lo, y>hi, z<lo, z>hi."""
    below, above = eye < lo, eye > hi
    bits = np.stack([below[:, 0], above[:, 0], below[:, 1], above[:, 1], below[:, 2], above[:, 2]], axis=1)
    return bits @ (1 << np.arange(6))


def _clip(poly: np.ndarray, axis: int, bound: float, keep_less: bool) -> tuple[np.ndarray, np.ndarray]:
    """One Sutherland-Hodgman step of padded polygons against x or y <= / >= bound: (polygons, counts).

    Each vertex yields the edge's crossing (if the edge crosses) then itself (if kept); slots yielding
    nothing repeat the previous kept point, so the output is padded the same way as the input.
    """
    prev = np.roll(poly, 1, axis=1)
    cin = poly[..., axis] <= bound if keep_less else poly[..., axis] >= bound
    cut = cin != np.roll(cin, 1, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cut, (bound - prev[..., axis]) / np.where(cut, poly[..., axis] - prev[..., axis], 1.0), 0.0)
    inter = prev + t[..., None] * (poly - prev)
    out = np.stack([inter, poly], axis=2).reshape(poly.shape[0], -1, 2)
    keep = np.stack([cut, cin], axis=2).reshape(poly.shape[0], -1)
    slot = np.where(keep, np.arange(keep.shape[1]), -1)
    last = np.maximum.accumulate(slot, axis=1)
    last = np.where(last < 0, last[:, -1:], last)
    return np.take_along_axis(out, np.maximum(last, 0)[..., None], axis=1), keep.sum(axis=1)


def polygon_areas(poly: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Shoelace areas (B,) of padded polygons; rows with fewer than 3 vertices have 0."""
    x, y = poly[..., 0], poly[..., 1]
    a = 0.5 * np.abs(np.sum(x * np.roll(y, -1, axis=1), axis=1) - np.sum(y * np.roll(x, -1, axis=1), axis=1))
    return np.where(count >= 3, a, 0.0)


def clipped_areas(poly: np.ndarray, count: np.ndarray, w: float, h: float) -> np.ndarray:
    """Areas (B,) of convex padded polygons clipped to the rectangle [0, w] x [0, h] (pixels).

    Polygons wholly inside keep their area; only the others go through the clip.
    """
    area = polygon_areas(poly, count)
    lo, hi = poly.min(axis=1), poly.max(axis=1)
    cut = (count >= 3) & ((lo[:, 0] < 0) | (lo[:, 1] < 0) | (hi[:, 0] > w) | (hi[:, 1] > h))
    if np.any(cut):
        sub, n = poly[cut], count[cut]
        for axis, bound, keep_less in ((0, 0.0, False), (0, w, True), (1, 0.0, False), (1, h, True)):
            out = sub[..., axis] > bound if keep_less else sub[..., axis] < bound
            if not np.any(out):
                continue                          # no polygon reaches past this side
            sub, kept = _clip(sub, axis, bound, keep_less)
            n = np.where(n >= 3, kept, 0)
        area[cut] = polygon_areas(sub, n)
    return area


def footprints(view: View, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per box (B, 3 corners each, world metres): viewport area in pixels of its near-cut projection, and the
    share of that projection inside the viewport in [0, 1] (0 when it has no area).

    A box wholly in front of the near plane takes its outline from the silhouette table; a box cut by the
    near plane takes the convex hull of its cut vertices.
    """
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    pts, valid = screen_points(view, box_corners(lo, hi))
    front = valid[:, :8].all(axis=1)
    code = region_codes(np.broadcast_to(view.eye, lo.shape), lo, hi)
    idx = _SILHOUETTE[code]
    poly = np.take_along_axis(pts[:, :8], idx[..., None], axis=1)
    same = np.all(poly[:, :, None] == poly[:, None, :], axis=-1) & np.tri(6, k=-1, dtype=bool)
    distinct = 6 - np.any(same, axis=2).sum(axis=1)            # outline corners that coincide count once
    count = np.where(front & (distinct >= 3), 6, 0)
    if not np.all(front):
        cut = ~front
        part = valid[cut] & (valid[cut].sum(axis=1, keepdims=True) >= 3)
        hull, n = hull_polygons(pts[cut], part)
        width = max(hull.shape[1], poly.shape[1])
        poly = np.concatenate([poly, np.repeat(poly[:, -1:], width - poly.shape[1], axis=1)], axis=1)
        poly[cut] = np.concatenate([hull, np.repeat(hull[:, -1:], width - hull.shape[1], axis=1)], axis=1)
        count[cut] = n
    area = clipped_areas(poly, count, view.width, view.height)
    whole = polygon_areas(poly, count)
    with np.errstate(divide="ignore", invalid="ignore"):
        visible = np.where(whole > 0, np.minimum(area / np.where(whole > 0, whole, 1.0), 1.0), 0.0)
    return area, visible


_SILHOUETTE = _silhouettes()
