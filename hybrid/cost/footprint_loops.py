"""The loops of ``hybrid.cost.footprint``, compiled by numba: a box's or polygon's steps one at a time (a frame
has a few dozen boxes, so numpy's per-call overhead was their cost). Imported where first called, so that a
process that never plans does not load numba."""

from __future__ import annotations

import numpy as np
from numba import njit


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
def box_areas(rot, eye, lo, hi, near, scale, w, h, outline, has_outline, faces, face_side, face_span, flat_outline):
    """Viewport area in pixels of each box's near-cut projection (see ``footprints``): (B,) from (B, 3) corners;
    the box tables are ``hybrid.cost.footprint``'s (outlines by eye code, faces, their sides and spans)."""
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
            corners = flat_outline if flat else outline[code]
            for k in range(len(corners)):
                pts[:, k] = rel[:, corners[k]]
            out[b] = abs(_project_area(pts, len(corners), scale, w, h))
            continue
        total = 0.0
        for f in range(6):
            if side[face_side[f]] and spans[face_span[f, 0]] and spans[face_span[f, 1]]:
                for k in range(4):
                    face[:, k] = rel[:, faces[f, k]]
                if cut:
                    _cut_face(face, near, pts)
                    total += _project_area(pts, 8, scale, w, h)
                else:
                    total += _project_area(face, 4, scale, w, h)
        out[b] = abs(total)
    return out


@njit(cache=True)
def polygon_areas(px: np.ndarray, py: np.ndarray, w: float, h: float) -> np.ndarray:
    """``_clipped_area`` of each row of (N, m) pixel coordinates."""
    out = np.empty(px.shape[0])
    for i in range(px.shape[0]):
        out[i] = _clipped_area(px[i], py[i], px.shape[1], w, h)
    return out
