"""Screen footprints of many world boxes at once: near-plane cut, viewport clip, area (pixels, numpy).

The batched counterpart of ``hybrid.cost.features.footprint_pixels``, computed another way. A ray from the
eye through a point of a convex body's projection leaves the body exactly once, through a face turned away
from the eye: the projections of a box's back faces tile its projection, whose boundary is the outline of
those faces. A box wholly in front of the near plane is one polygon, its outline (4 or 6 corners, from a
table by where the eye lies; a box flat in z, its rectangle); a box reaching behind the near plane is its back faces, each cut at the plane
first (the cut box's back faces are the cut faces; its cap on the near plane faces the eye). Every polygon is
clipped to the viewport and its area summed per box. Vertices are the reference's corners and near-plane
crossings of the box edges (within rounding: a crossing is found along the face's edge as it runs), projected
the same way and rounded to 1e-6 px.

A frame has a few dozen tiles, so the time is set by the number of array operations more than their size:
each step works on every polygon at once, coordinates leading every array so that a step runs over all
vertices contiguously, and the viewport clip is a clamp integrated in closed form (``clipped_signed_areas_xy``).
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


def _silhouettes() -> tuple[np.ndarray, np.ndarray]:
    """Per eye position code (per axis: bit 0 the eye above the box's low side, bit 1 below its high side; code
    = x + 4 y + 16 z), the box's outline as 6 corner indices in order along it (a 4-corner outline repeats its
    last), and whether the code has one (an eye outside a box of some extent on every axis): the boundary of its
    back faces, the edges that belong to exactly one of them (Schmalstieg and Tobler's table of box outlines)."""
    table, ok = np.zeros((64, 6), np.int64), np.zeros(64, bool)
    for code in range(64):
        states = [(code >> (2 * a)) & 3 for a in range(3)]
        if any(st != 3 and st == 0 for st in states) or all(st == 3 for st in states):
            continue                            # an axis on which the box has no extent, or the eye inside it
        count: dict = {}
        for f, (axis, hi_side) in enumerate(zip(_FACE_AXIS, _FACE_HI)):
            if (states[axis] >> int(hi_side)) & 1:
                for k in range(4):
                    e = frozenset((int(_FACES[f, k]), int(_FACES[f, (k + 1) % 4])))
                    count[e] = count.get(e, 0) + 1
        edges = [tuple(e) for e, c in count.items() if c == 1]
        cycle = [edges[0][0], edges[0][1]]
        rest = edges[1:]
        while rest:
            nxt = next(e for e in rest if cycle[-1] in e)
            rest.remove(nxt)
            cycle.append(nxt[0] if nxt[1] == cycle[-1] else nxt[1])
        cycle = cycle[:-1]                      # back at the start
        table[code] = cycle + [cycle[-1]] * (6 - len(cycle))
        ok[code] = True
    return table, ok


def _eye_space(view: View, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The corners of B boxes ((B, 3) min and max, world metres) in eye space (metres, the camera looking down
    -z), coordinates first: (3, B, 8), corner c = 4 (x is hi) + 2 (y is hi) + (z is hi)."""
    corners = np.where(_CORNER_BITS.T[:, None, :], hi.T[:, :, None], lo.T[:, :, None])
    corners -= np.asarray(view.eye, dtype=np.float64)[:, None, None]
    return (view.rotation() @ corners.reshape(3, -1)).reshape(3, -1, 8)


def _near(view: View) -> float:
    """The near plane's depth as the reference cuts at it: a hair in front, so points on it count as cut."""
    return view.near * (1 + 1e-9)


def near_cut(view: View, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(B,) whether each box (world metres) reaches behind the near plane."""
    return np.any(-_eye_space(view, np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64))[2]
                  < _near(view), axis=1)


def _project(view: View, p: np.ndarray) -> np.ndarray:
    """Eye-space points (3, ...) (coordinates first) in front of the near plane to pixels (2, ...), x then y,
    rounded to 1e-6 px."""
    tan = view.tan_half_fov
    out = p[:2] / p[2] * _column(-0.5 * view.width / (tan * view.aspect), 0.5 * view.height / tan, p.ndim) \
        + _column(0.5 * view.width, 0.5 * view.height, p.ndim)
    return out.round(6, out=out)


def _column(x: float, y: float, ndim: int) -> np.ndarray:
    """(2, 1, ...) of x and y, broadcasting against (2, ...) coordinates of ``ndim`` axes."""
    return np.array([x, y]).reshape((2,) + (1,) * (ndim - 1))


class _Next(dict):
    """Index arrays i -> (i + 1) mod m, one per polygon width m, made once."""

    def __missing__(self, m):
        self[m] = np.roll(np.arange(m), -1)
        return self[m]


_NEXT = _Next()
_OUTLINE, _HAS_OUTLINE = _silhouettes()
_PAD = {k: np.minimum(np.arange(8), k - 1) for k in (4, 6, 8)}            # k vertices padded to 8 by the last


def clipped_signed_areas(poly: np.ndarray, w: float, h: float) -> np.ndarray:
    """Signed areas (N,) of convex padded polygons (N, m, 2) clipped to the rectangle [0, w] x [0, h] (pixels),
    with the sign of each polygon's own orientation (``clipped_signed_areas_xy`` of their coordinates)."""
    return clipped_signed_areas_xy(np.moveaxis(np.asarray(poly, dtype=np.float64), -1, 0), w, h)


def clipped_signed_areas_xy(p: np.ndarray, w: float, h: float) -> np.ndarray:
    """Signed areas (N,) of convex padded polygons given as (2, N, m) x and y pixel coordinates, clipped to the
    rectangle [0, w] x [0, h], with the sign of each polygon's own orientation.

    Clamping (x, y) to the rectangle is the nearest-point projection onto it. It maps the polygon's boundary to
    a closed path that winds once around every point of the intersection and never around a point outside the
    rectangle (the straight path from a point outside to its projection never enters the rectangle's interior),
    so the intersection's signed area is that path's -integral of y dx: per edge, the integral of the clamped y
    over the part of the edge whose x lies in [0, w] (x is monotone along an edge, so that part runs from the
    clamped x of its start to that of its end). Along it y is linear, so the integral is the x span times the
    mean of y clamped to [0, h] between the part's end values, a closed form. Repeated vertices (padding) are
    edges of no span and add nothing; so do vertical edges.
    """
    m = p.shape[2]
    q = p[:, :, _NEXT[m]]                                                      # each edge's end
    cx = np.minimum(np.maximum(np.stack([p[0], q[0]]), 0.0), w)               # the edge's x span over [0, w]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (cx - p[0]) / (q[0] - p[0])
    t = np.fmin(np.fmax(t, 0.0), 1.0)                                         # a vertical edge (0 / 0): its start
    y = p[1] + t * (q[1] - p[1])                                              # y at the span's ends (2, N, m)
    lo, hi = np.minimum(y[0], y[1]), np.maximum(y[0], y[1])
    a, b = np.minimum(np.maximum(lo, 0.0), h), np.minimum(np.maximum(hi, 0.0), h)
    span = hi - lo
    with np.errstate(divide="ignore", invalid="ignore"):                      # mean of clamp(y) for y in [lo, hi]
        mean = ((b - a) * (a + b) * 0.5 + h * np.maximum(hi - np.maximum(lo, h), 0.0)) / span
    mean = np.where(span > 0, mean, a)
    return -np.einsum("ij,ij->i", cx[1] - cx[0], mean)


def _cut_faces(face: np.ndarray, near: float) -> np.ndarray:
    """Faces (3, N, 4) in eye space (coordinates first) cut at depth >= near: (3, N, 8) closed polygons whose
    projections have the cut faces' signed areas.

    Each edge k yields vertex k and the point where the edge crosses the plane (vertex k again if it does not).
    Points behind the plane are then replaced by one crossing of their face: the face meets the plane in a line,
    so what replaced them runs along that line and back, which adds no area to the projection (the clipped
    face is what is left). A face wholly behind becomes a point in front of the eye (no area)."""
    n = face.shape[1]
    nxt = face[:, :, _NEXT[4]]
    depth = -face[2]
    front = depth >= near
    cross = front != front[:, _NEXT[4]]
    step = depth - depth[:, _NEXT[4]]
    t = (depth - near) / np.where(cross, step, 1.0)                            # along edge k where it crosses
    hit = face + t * (nxt - face)
    pts = np.empty((3, n, 4, 2))
    pts[..., 0] = face
    pts[..., 1] = np.where(cross, hit, face)
    keep = np.empty((n, 4, 2), bool)
    keep[..., 0], keep[..., 1] = front, front | cross
    anchor = np.where(cross.any(axis=1), hit[:, np.arange(n), cross.argmax(axis=1)], _AHEAD)
    return np.where(keep.reshape(n, 8), pts.reshape(3, n, 8), anchor[:, :, None])


_AHEAD = np.array([0.0, 0.0, -1.0])[:, None]                                # a point in front of the eye


def footprints(view: View, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Per box (B, 3 corners each, world metres): viewport area in pixels of its near-cut projection.

    A box wholly in front of the near plane with some extent on every axis projects to its outline, one
    polygon of 4 or 6 corners looked up by where the eye is (``_silhouettes``), and one flat in z to its
    rectangle; any other box (flat in x or y, or reaching behind the near plane) to its back faces, cut at the
    near plane when any reaches behind it. All polygons
    are projected and clipped to the viewport in one pass; a box's areas are then summed."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    b = lo.shape[0]
    rel = _eye_space(view, lo, hi)                             # (3, B, 8)
    near = _near(view)
    eye = np.asarray(view.eye, dtype=np.float64)
    side = np.concatenate([eye > lo, eye < hi], axis=1)        # (B, 6): per axis the low, then the high face is back
    code = side @ _CODE_WEIGHTS
    cut = (rel[2] > -near).any(axis=1)
    spans = (hi - lo) > 0
    flat = spans[:, 0] & spans[:, 1] & ~spans[:, 2]             # a rectangle at one height: its outline is itself
    outline = (_HAS_OUTLINE[code] | flat) & ~cut
    sbox = np.flatnonzero(outline)
    corner = np.where(flat[sbox, None], _FLAT_OUTLINE, _OUTLINE[code[sbox]])
    sil = np.take(rel.reshape(3, -1), sbox[:, None] * 8 + corner, axis=1)                   # (3, S, 6)
    if len(sbox) == b:                                          # every box one polygon (in box order): no faces
        return np.abs(clipped_signed_areas_xy(_project(view, sil), float(view.width), float(view.height)))
    back = side[:, _FACE_SIDE] & spans[:, _FACE_SPAN[:, 0]] & spans[:, _FACE_SPAN[:, 1]]
    back[outline] = False
    box, fid = np.nonzero(back)
    face = np.take(rel.reshape(3, -1), box[:, None] * 8 + _FACES[fid], axis=1)             # (3, N, 4)
    if cut.any():
        face = _cut_faces(face, near)
    m = max(6, face.shape[2])
    poly = _project(view, np.concatenate([sil[:, :, _PAD[6][:m]], face[:, :, _PAD[face.shape[2]][:m]]], axis=1))
    area = clipped_signed_areas_xy(poly, float(view.width), float(view.height))
    return np.abs(np.bincount(np.concatenate([sbox, box]), area, minlength=b))


_CODE_WEIGHTS = np.array([1, 4, 16, 2, 8, 32])             # the eye position code of ``_silhouettes`` from ``side``
_FACE_SIDE = np.array([0, 3, 1, 4, 2, 5])                  # face f's column of ``side`` (faces in _FACES order)
_FLAT_OUTLINE = np.array([0, 2, 6, 4, 4, 4])               # a box flat in z: its low z face, padded to 6 corners
