"""Screen footprints of many world boxes at once: near-plane cut, viewport clip, area (pixels, numpy).

The batched counterpart of ``hybrid.cost.features.footprint_pixels``, computed another way. A ray from the
eye through a point of a convex body's projection leaves the body exactly once, through a face turned away
from the eye: the projections of a box's back faces tile its projection. So the footprint clipped to the
viewport is the sum of the back faces' projected quads clipped to the viewport, each a convex polygon, every
face of every box in one pass: no convex hull, no silhouette, no sequential clip. Faces reaching behind the
near plane are cut at it first (the cut box's back faces are the cut faces; its cap on the near plane faces
the eye). Vertices are the reference's: the same corners and near-plane crossings of the box edges (from
the lower corner index to the higher), projected the same way and rounded to 1e-6 px.
"""
from __future__ import annotations

import numpy as np

from hybrid.camera.view import View

# box corner index = 4 * (x is hi) + 2 * (y is hi) + (z is hi), as in features.footprint_pixels
_CORNER_BITS = np.array([[(c >> 2) & 1, (c >> 1) & 1, c & 1] for c in range(8)], dtype=bool)
# the six faces as corner cycles: (axis, side) = (x, lo), (x, hi), (y, lo), (y, hi), (z, lo), (z, hi)
_FACES = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]])
_FACE_AXIS = np.array([0, 0, 1, 1, 2, 2])
_FACE_HI = np.array([False, True, False, True, False, True])
_FACE_SPAN = np.array([[(a + 1) % 3, (a + 2) % 3] for a in _FACE_AXIS])  # the two axes each face spans
_EDGE_LO = np.minimum(_FACES, np.roll(_FACES, -1, axis=1))         # each face edge from its lower corner index
_EDGE_HI = np.maximum(_FACES, np.roll(_FACES, -1, axis=1))


def box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(B, 8, 3) world corners of B boxes given their (B, 3) min and max corners, in footprint order."""
    return np.where(_CORNER_BITS[None], hi[:, None, :], lo[:, None, :])


def _eye_space(view: View, corners: np.ndarray) -> np.ndarray:
    """Corners (B, 8, 3) in eye space (metres, the camera looking down -z)."""
    b = corners.shape[0]
    return ((corners - view.eye).reshape(-1, 3) @ view.rotation().T).reshape(b, 8, 3)


def _near(view: View) -> float:
    """The near plane's depth as the reference cuts at it: a hair in front, so points on it count as cut."""
    return view.near * (1 + 1e-9)


def near_cut(view: View, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(B,) whether each box (world metres) reaches behind the near plane."""
    return np.any(-_eye_space(view, box_corners(lo, hi))[..., 2] < _near(view), axis=1)


def _project(view: View, pts: np.ndarray) -> np.ndarray:
    """Eye-space points (..., 3) in front of the near plane to pixels (..., 2), rounded to 1e-6 px."""
    tan = view.tan_half_fov
    x = (pts[..., 0] / -pts[..., 2]) / (tan * view.aspect)
    y = (pts[..., 1] / -pts[..., 2]) / tan
    return np.round(np.stack([(x + 1) * 0.5 * view.width, (1 - y) * 0.5 * view.height], axis=-1), 6)


class _Next(dict):
    """Index arrays i -> (i + 1) mod m, one per polygon width m, made once."""

    def __missing__(self, m):
        self[m] = np.roll(np.arange(m), -1)
        return self[m]


_NEXT = _Next()


def signed_areas(poly: np.ndarray) -> np.ndarray:
    """Shoelace signed areas (...) of padded polygons (..., m, 2): positive counter-clockwise in (x, y)."""
    nxt = poly[..., _NEXT[poly.shape[-2]], :]
    return 0.5 * np.sum(poly[..., 0] * nxt[..., 1] - nxt[..., 0] * poly[..., 1], axis=-1)


def clipped_signed_areas(poly: np.ndarray, w: float, h: float) -> np.ndarray:
    """Signed areas (B,) of convex padded polygons (B, m, 2) clipped to the rectangle [0, w] x [0, h] (pixels),
    with the sign of each polygon's own orientation.

    Green's theorem over the boundary of the intersection: the polygon's edges clipped to the rectangle
    (Liang-Barsky) and the rectangle's sides clipped to the polygon (Cyrus-Beck, the polygon being convex), both
    run the polygon's way round. Repeated vertices (padding) are edges of no length and add nothing; a polygon
    of no area (a point, or a segment: a box face seen from a flat box's side) has none clipped either.
    """
    m = poly.shape[1]
    sa = signed_areas(poly)
    orient = np.where(sa < 0, -1.0, 1.0)
    a, d = poly, poly[:, _NEXT[m]] - poly                                       # edges a -> a + d, (B, m, 2)
    lim = np.array([w, h])
    with np.errstate(divide="ignore", invalid="ignore"):
        t_a, t_b = -a / d, (lim - a) / d
    moving, within = d != 0, (a >= 0) & (a <= lim)
    t_in = np.where(moving, np.minimum(t_a, t_b), np.where(within, -np.inf, np.inf)).max(axis=-1)
    t_out = np.where(moving, np.maximum(t_a, t_b), np.where(within, np.inf, -np.inf)).min(axis=-1)
    t0, t1 = np.clip(t_in, 0.0, 1.0), np.clip(t_out, 0.0, 1.0)
    p0, p1 = a + t0[..., None] * d, a + t1[..., None] * d
    own = np.where(t1 > t0, p0[..., 0] * p1[..., 1] - p1[..., 0] * p0[..., 1], 0.0).sum(axis=1)
    # the rectangle's sides, counter-clockwise in (x, y) (reversed for clockwise polygons), clipped to the polygon
    r0 = np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]])
    r1 = r0[[1, 2, 3, 0]]
    ccw = (orient > 0)[:, None, None]
    q0 = np.where(ccw, r0, r1)[:, :, None, :]                                  # (B, 4, 1, 2)
    dq = np.where(ccw, r1, r0)[:, :, None, :] - q0
    ea, ed = a[:, None], d[:, None]                                            # (B, 1, m, 2)
    s = orient[:, None, None]
    fa = s * (ed[..., 0] * (q0[..., 1] - ea[..., 1]) - ed[..., 1] * (q0[..., 0] - ea[..., 0]))   # (B, 4, m)
    fb = s * (ed[..., 0] * dq[..., 1] - ed[..., 1] * dq[..., 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        root = -fa / fb
    u0 = np.maximum(np.where(fb > 0, root, -np.inf).max(axis=-1), 0.0)
    u1 = np.minimum(np.where(fb < 0, root, np.inf).min(axis=-1), 1.0)
    # a side parallel to an edge is kept only strictly inside it, so a side along an edge counts once
    real = (d[..., 0] != 0) | (d[..., 1] != 0)                                # (B, m): edges of some length
    blocked = np.any((fb == 0) & (fa <= 0) & real[:, None], axis=-1)
    g0, g1 = q0[:, :, 0] + u0[..., None] * dq[:, :, 0], q0[:, :, 0] + u1[..., None] * dq[:, :, 0]
    side = np.where((u1 > u0) & ~blocked, g0[..., 0] * g1[..., 1] - g1[..., 0] * g0[..., 1], 0.0).sum(axis=1)
    return np.where(sa == 0, 0.0, 0.5 * (own + side))           # a point or a segment bounds nothing


def _cut_faces(rel: np.ndarray, near: float) -> np.ndarray:
    """Faces (B, 6, 4, 3) of boxes' eye-space corners cut at depth >= near: (B, 6, 8, 3) padded polygons.

    One Sutherland-Hodgman step: each vertex yields the crossing of the edge into it (if the edge crosses),
    then itself (if in front); empty slots repeat the previous point, so a face wholly behind collapses to a
    point (no area). Crossings are computed along box edges from their lower corner index, as the reference.
    """
    face = rel[:, _FACES]                                                      # (B, 6, 4, 3)
    depth = -face[..., 2]
    keep = depth >= near
    ra, rb = rel[:, _EDGE_LO], rel[:, _EDGE_HI]                                # edge k: corner k -> k + 1
    da, db = -ra[..., 2], -rb[..., 2]
    cross = (da - near) * (db - near) < 0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cross, (near - da) / np.where(cross, db - da, 1.0), 0.0)
    hit = ra + t[..., None] * (rb - ra)
    # the crossing of edge k (vertex k -> k + 1) comes before vertex k + 1
    into = np.roll(hit, 1, axis=2)
    into_ok = np.roll(cross, 1, axis=2)
    pts = np.stack([into, face], axis=3).reshape(*face.shape[:2], 8, 3)
    ok = np.stack([into_ok, keep], axis=3).reshape(*face.shape[:2], 8)
    slot = np.where(ok, np.arange(8), -1)
    last = np.maximum.accumulate(slot, axis=2)
    last = np.where(last < 0, last[..., -1:], last)                           # leading gaps take the final point
    out = np.take_along_axis(pts, np.maximum(last, 0)[..., None], axis=2)
    empty = ~ok.any(axis=2)
    return np.where(empty[..., None, None], np.array([0.0, 0.0, -1.0]), out)   # a harmless point, no area


def footprints(view: View, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Per box (B, 3 corners each, world metres): viewport area in pixels of its near-cut projection."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    b = lo.shape[0]
    rel = _eye_space(view, box_corners(lo, hi))
    near = _near(view)
    eye = np.asarray(view.eye, dtype=np.float64)
    e, l, u = eye[_FACE_AXIS][None], lo[:, _FACE_AXIS], hi[:, _FACE_AXIS]
    back = np.where(_FACE_HI[None], e < u, e > l)                              # (B, 6): turned away from the eye
    back &= np.all((hi - lo)[:, _FACE_SPAN] > 0, axis=2)                       # a face of no area adds none
    cut = np.any(-rel[..., 2] < near, axis=1)
    m = 8 if cut.any() else 4
    poly = np.empty((b, 6, m, 2))
    front = ~cut
    corners = _project(view, rel[front])                                       # (F, 8, 2)
    poly[front] = corners[:, _FACES[:, [0, 1, 2, 3, 3, 3, 3, 3][:m]]]
    if cut.any():
        poly[cut] = _project(view, _cut_faces(rel[cut], near))
    flat = poly.reshape(b * 6, m, 2)
    w, h = float(view.width), float(view.height)
    # boxes whose projection reaches past the viewport take the clip; the others' faces are wholly inside
    crosses = cut.copy()
    crosses[front] = np.any((corners < 0) | (corners > np.array([w, h])), axis=(1, 2))
    on = back.reshape(-1)
    clip = on & np.repeat(crosses, 6)
    whole = on & ~clip
    face_area = np.zeros(b * 6)
    face_area[whole] = signed_areas(flat[whole])
    if clip.any():
        face_area[clip] = clipped_signed_areas(flat[clip], w, h)
    return np.abs(face_area.reshape(b, 6).sum(axis=1))
