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

A frame has a few dozen tiles: as numpy array operations the time was set by their number, not their size,
so the boxes are walked one by one in a loop compiled by numba, with the same steps. The viewport clip is a
clamp integrated in closed form (``_clipped_area``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

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
            continue  # an axis on which the box has no extent, or the eye inside it
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
        cycle = cycle[:-1]  # back at the start
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
    return np.any(
        -_eye_space(view, np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64))[2] < _near(view), axis=1
    )


_OUTLINE, _HAS_OUTLINE = _silhouettes()
_FACE_SIDE = np.array([0, 3, 1, 4, 2, 5])  # face f's column of ``side`` (faces in _FACES order)
_FLAT_OUTLINE = np.array([0, 2, 6, 4])  # a box flat in z: its low z face


@njit(cache=True)
def _clipped_area(px: np.ndarray, py: np.ndarray, n: int, w: float, h: float) -> float:
    """Signed area of the convex polygon px[:n], py[:n] (pixels) clipped to the rectangle [0, w] x [0, h], with
    the sign of the polygon's own orientation.

    Clamping (x, y) to the rectangle is the nearest-point projection onto it. It maps the polygon's boundary to
    a closed path that winds once around every point of the intersection and never around a point outside the
    rectangle (the straight path from a point outside to its projection never enters the rectangle's interior),
    so the intersection's signed area is that path's -integral of y dx: per edge, the integral of the clamped y
    over the part of the edge whose x lies in [0, w] (x is monotone along an edge, so that part runs from the
    clamped x of its start to that of its end). Along it y is linear, so the integral is the x span times the
    mean of y clamped to [0, h] between the part's end values, a closed form. Repeated vertices (padding) are
    edges of no span and add nothing; so do vertical edges.
    """
    total = 0.0
    for k in range(n):
        j = k + 1 if k + 1 < n else 0
        x0, y0, x1, y1 = px[k], py[k], px[j], py[j]
        c0, c1 = min(max(x0, 0.0), w), min(max(x1, 0.0), w)
        if c1 == c0:
            continue
        t0 = min(max((c0 - x0) / (x1 - x0), 0.0), 1.0)
        t1 = min(max((c1 - x0) / (x1 - x0), 0.0), 1.0)
        ya, yb = y0 + t0 * (y1 - y0), y0 + t1 * (y1 - y0)
        lo, hi = min(ya, yb), max(ya, yb)
        a, b = min(max(lo, 0.0), h), min(max(hi, 0.0), h)
        span = hi - lo
        mean = ((b - a) * (a + b) * 0.5 + h * max(hi - max(lo, h), 0.0)) / span if span > 0 else a
        total -= (c1 - c0) * mean
    return total


@njit(cache=True)
def _cut_face(face: np.ndarray, near: float, out: np.ndarray) -> None:
    """A face (3, 4) in eye space cut at depth >= near, into ``out`` (3, 8): a closed polygon whose projection
    has the cut face's signed area.

    Each edge k yields vertex k and the point where the edge crosses the plane (vertex k again if it does not).
    Points behind the plane are then replaced by one crossing of the face: the face meets the plane in a line,
    so what replaced them runs along that line and back, which adds no area to the projection (the clipped
    face is what is left). A face wholly behind becomes a point in front of the eye (no area)."""
    anchor = (0.0, 0.0, -1.0)
    found = False
    for k in range(4):
        j = (k + 1) % 4
        dk, dj = -face[2, k], -face[2, j]
        front = dk >= near
        cross = front != (dj >= near)
        t = (dk - near) / (dk - dj) if cross else 0.0
        for r in range(3):
            hit = face[r, k] + t * (face[r, j] - face[r, k])
            out[r, 2 * k] = face[r, k] if front else np.nan
            out[r, 2 * k + 1] = hit if cross else (face[r, k] if front else np.nan)
        if cross and not found:
            anchor = (out[0, 2 * k + 1], out[1, 2 * k + 1], out[2, 2 * k + 1])
            found = True
    for c in range(8):
        if np.isnan(out[0, c]):
            out[0, c], out[1, c], out[2, c] = anchor


@njit(cache=True)
def _project_area(pts: np.ndarray, n: int, scale: np.ndarray, w: float, h: float) -> float:
    """Signed viewport-clipped area (pixels) of the projection of eye-space points pts[:, :n] (in front of the
    near plane), projected as the reference does and rounded to 1e-6 px; scale is (sx, sy, ox, oy)."""
    px, py = np.empty(n), np.empty(n)
    for c in range(n):
        px[c] = np.rint((pts[0, c] / pts[2, c] * scale[0] + scale[2]) * 1e6) / 1e6
        py[c] = np.rint((pts[1, c] / pts[2, c] * scale[1] + scale[3]) * 1e6) / 1e6
    return _clipped_area(px, py, n, w, h)


@njit(cache=True)
def _box_areas(rot, eye, lo, hi, near, scale, w, h, outline, has_outline):
    """Viewport area in pixels of each box's near-cut projection (see ``footprints``): (B,) from (B, 3) corners."""
    out = np.zeros(lo.shape[0])
    rel, pts, face = np.empty((3, 8)), np.empty((3, 8)), np.empty((3, 4))
    side, spans = np.empty(6, np.bool_), np.empty(3, np.bool_)
    for b in range(lo.shape[0]):
        cut = False
        for c in range(8):
            dx = (hi[b, 0] if (c >> 2) & 1 else lo[b, 0]) - eye[0]
            dy = (hi[b, 1] if (c >> 1) & 1 else lo[b, 1]) - eye[1]
            dz = (hi[b, 2] if c & 1 else lo[b, 2]) - eye[2]
            for r in range(3):
                rel[r, c] = rot[r, 0] * dx + rot[r, 1] * dy + rot[r, 2] * dz
            cut |= rel[2, c] > -near
        code = 0
        for a in range(3):
            side[a], side[a + 3] = eye[a] > lo[b, a], eye[a] < hi[b, a]
            spans[a] = hi[b, a] - lo[b, a] > 0
            code += (1 << (2 * a)) * side[a] + (2 << (2 * a)) * side[a + 3]
        flat = spans[0] and spans[1] and not spans[2]
        if (has_outline[code] or flat) and not cut:
            corners = _FLAT_OUTLINE if flat else outline[code]
            for k in range(len(corners)):
                pts[:, k] = rel[:, corners[k]]
            out[b] = abs(_project_area(pts, len(corners), scale, w, h))
            continue
        total = 0.0
        for f in range(6):
            if side[_FACE_SIDE[f]] and spans[_FACE_SPAN[f, 0]] and spans[_FACE_SPAN[f, 1]]:
                for k in range(4):
                    face[:, k] = rel[:, _FACES[f, k]]
                if cut:
                    _cut_face(face, near, pts)
                    total += _project_area(pts, 8, scale, w, h)
                else:
                    total += _project_area(face, 4, scale, w, h)
        out[b] = abs(total)
    return out


def footprints(view: View, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Per box (B, 3 corners each, world metres): viewport area in pixels of its near-cut projection.

    A box wholly in front of the near plane with some extent on every axis projects to its outline, one
    polygon of 4 or 6 corners looked up by where the eye is (``_silhouettes``), and one flat in z to its
    rectangle; any other box (flat in x or y, or reaching behind the near plane) to its back faces, cut at the
    near plane when any corner reaches behind it, their signed areas summed."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    tan = view.tan_half_fov
    scale = np.array(
        [-0.5 * view.width / (tan * view.aspect), 0.5 * view.height / tan, 0.5 * view.width, 0.5 * view.height]
    )
    return _box_areas(
        np.ascontiguousarray(view.rotation(), dtype=np.float64),
        np.asarray(view.eye, dtype=np.float64),
        np.ascontiguousarray(lo.reshape(-1, 3)),
        np.ascontiguousarray(hi.reshape(-1, 3)),
        _near(view),
        scale,
        float(view.width),
        float(view.height),
        _OUTLINE,
        _HAS_OUTLINE,
    )


@njit(cache=True)
def _polygon_areas(px: np.ndarray, py: np.ndarray, w: float, h: float) -> np.ndarray:
    """``_clipped_area`` of each row of (N, m) pixel coordinates."""
    out = np.empty(px.shape[0])
    for i in range(px.shape[0]):
        out[i] = _clipped_area(px[i], py[i], px.shape[1], w, h)
    return out


def clipped_signed_areas(poly: np.ndarray, w: float, h: float) -> np.ndarray:
    """Signed areas (N,) of convex padded polygons (N, m, 2) (pixels) clipped to the rectangle [0, w] x [0, h],
    with the sign of each polygon's own orientation (``_clipped_area``)."""
    p = np.asarray(poly, dtype=np.float64)
    return _polygon_areas(np.ascontiguousarray(p[..., 0]), np.ascontiguousarray(p[..., 1]), float(w), float(h))
