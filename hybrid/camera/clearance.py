"""Where the eye is allowed: above the drawn terrain surface by at least the near-plane distance.

From below the surface, inside a mountain, or with the near plane cutting the ground under the eye, the
full-resolution reference and the strategies see different things (back faces, tile boxes entered from
below, clipped triangles), so such views are refused where a user gives them (render, runs); the stress
harness draws them on purpose and flags them.
"""
from __future__ import annotations

import numpy as np

from hybrid.camera.view import View
from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import HeightField


def eye_clearance(hf: HeightField, eye) -> float:
    """Metres from the drawn (triangulated) surface straight below the eye up to the eye; +inf off the terrain."""
    x, y, z = (float(v) for v in np.asarray(eye, dtype=np.float64).reshape(3))
    w, d = hf.extent
    if not (hf.origin[0] <= x <= hf.origin[0] + w and hf.origin[1] <= y <= hf.origin[1] + d):
        return float("inf")
    return z - float(hf.ground_height(x, y))


def check_eye_above(hf: HeightField, view: View, what: str = "view") -> None:
    """Refuse a view whose eye is below the terrain surface or closer to it than the near plane (metres)."""
    c = eye_clearance(hf, view.eye)
    if c < view.near:
        where = "below the terrain surface" if c < 0 else f"within the near plane ({view.near:g} m) of the surface"
        raise TerrabenchError(
            f"{what}: the eye at ({view.eye[0]:.1f}, {view.eye[1]:.1f}, {view.eye[2]:.1f}) m is {abs(c):.2f} m "
            f"{'below' if c < 0 else 'above'} the ground, {where}; methods and the reference would not draw the "
            "same scene: raise the eye")
