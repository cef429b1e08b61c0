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
clamp integrated in closed form (``footprint_loops._clipped_area``).
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
    from .footprint_loops import box_areas

    return box_areas(
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
        _FACES,
        _FACE_SIDE,
        _FACE_SPAN,
        _FLAT_OUTLINE,
    )


def clipped_signed_areas(poly: np.ndarray, w: float, h: float) -> np.ndarray:
    """Signed areas (N,) of convex padded polygons (N, m, 2) (pixels) clipped to the rectangle [0, w] x [0, h],
    with the sign of each polygon's own orientation (``footprint_loops._clipped_area``)."""
    p = np.asarray(poly, dtype=np.float64)
    from .footprint_loops import polygon_areas

    return polygon_areas(np.ascontiguousarray(p[..., 0]), np.ascontiguousarray(p[..., 1]), float(w), float(h))
