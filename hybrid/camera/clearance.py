"""Where the eye may be, in world metres (x east, y north, z up).

Users' views must have the eye above the drawn terrain surface by at least the near-plane distance: from
below the surface, inside a mountain, or with the near plane cutting the ground under the eye, the
full-resolution reference and the strategies see different things, so such views are refused where a user
gives them (render, runs); the stress harness draws them on purpose and flags them.

Presets place their eyes from the height samples: over the local relief, and high enough that the ground
ahead stays below a given elevation angle (so that a level view shows sky above it); no peak between the
points of a sparse stencil is missed.
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


def eye_too_low(clearance: float, view: View) -> bool:
    """True when an eye ``clearance`` metres above the ground is below it or within the view's near plane."""
    return clearance < view.near


def check_eye_above(hf: HeightField, view: View, what: str = "view") -> None:
    """Refuse a view whose eye is below the terrain surface or closer to it than the near plane (metres)."""
    c = eye_clearance(hf, view.eye)
    if eye_too_low(c, view):
        where = "below the terrain surface" if c < 0 else f"within the near plane ({view.near:g} m) of the surface"
        raise TerrabenchError(
            f"{what}: the eye at ({view.eye[0]:.1f}, {view.eye[1]:.1f}, {view.eye[2]:.1f}) m is {abs(c):.2f} m "
            f"{'below' if c < 0 else 'above'} the ground, {where}; methods and the reference would not draw the "
            "same scene: raise the eye"
        )


_CHUNK = 1 << 22  # elements gathered at once (bounds the memory of long flights on large grids)


def _chunks(n: int, per_item: int):
    """Slices of range(n) with at most _CHUNK // per_item items each (at least one)."""
    step = max(1, _CHUNK // max(per_item, 1))
    for s in range(0, n, step):
        yield slice(s, min(s + step, n))


def ground_extremes(hf: HeightField, x, y, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest height sample (world z, metres) within ``radius`` metres along x and y of each world
    point (x, y), the corners of the cell holding the point included; points off the grid use its edge. A stored
    terrain answers windows too large to gather from its tiles' bounds (``window_extremes``): lower and upper
    bounds that hold."""
    x = np.atleast_1d(np.asarray(x, dtype=np.float64))
    y = np.atleast_1d(np.asarray(y, dtype=np.float64))
    fi = np.floor((y - hf.origin[1]) / hf.spacing_y).astype(np.int64)
    fj = np.floor((x - hf.origin[0]) / hf.spacing_x).astype(np.int64)
    ki, kj = int(np.ceil(radius / hf.spacing_y)), int(np.ceil(radius / hf.spacing_x))
    bounds = getattr(hf, "window_extremes", None)
    if bounds is not None and (2 * ki + 3) * (2 * kj + 3) > _CHUNK:  # a stored terrain: its tiles' bounds
        lo, hi = bounds(
            np.clip(fi - ki, 0, hf.rows - 1),
            np.clip(fi + ki + 1, 0, hf.rows - 1),
            np.clip(fj - kj, 0, hf.cols - 1),
            np.clip(fj + kj + 1, 0, hf.cols - 1),
        )
        return hf.origin[2] + lo, hf.origin[2] + hi
    di, dj = np.arange(-ki, ki + 2), np.arange(-kj, kj + 2)
    lo, hi = np.empty(len(x)), np.empty(len(x))
    for s in _chunks(len(x), len(di) * len(dj)):
        rows = np.clip(fi[s, None] + di, 0, hf.rows - 1)
        cols = np.clip(fj[s, None] + dj, 0, hf.cols - 1)
        win = hf.heights[rows[:, :, None], cols[:, None, :]]
        lo[s], hi[s] = win.min(axis=(1, 2)), win.max(axis=(1, 2))
    return hf.origin[2] + lo, hf.origin[2] + hi


def clear_heights(hf: HeightField, x, y, radius: float, floor: float, relief_frac: float) -> np.ndarray:
    """Eye heights (world z, metres) over each world (x, y): the highest sample within ``radius`` metres plus a
    margin of max(floor, relief_frac x the local relief there), the relief being highest minus lowest sample."""
    lo, hi = ground_extremes(hf, x, y, radius)
    return hi + np.maximum(float(floor), float(relief_frac) * (hi - lo))


def horizon_heights(hf: HeightField, x, y, heading, half_width_rad: float, rise_rad: float) -> np.ndarray:
    """Lowest eye heights (world z, metres) at world (x, y) from which the ground over the footprint rises at
    most ``rise_rad`` above the horizontal along most directions within ``half_width_rad`` of the unit xy
    ``heading``: along 9 directions across that field, sampled every half cell to the footprint's far side,
    the median of their needs (a lone peak blocks the sky over a few columns, not the upper part)."""
    x = np.atleast_1d(np.asarray(x, dtype=np.float64))
    y = np.atleast_1d(np.asarray(y, dtype=np.float64))
    w, d = hf.extent
    step = 0.5 * min(hf.spacing_x, hf.spacing_y)
    t = np.arange(1, int(np.hypot(w, d) / step) + 1) * step
    az = np.arctan2(heading[1], heading[0]) + np.linspace(-half_width_rad, half_width_rad, 9)
    dirs = np.stack([np.cos(az), np.sin(az)], 1)
    ox, oy = hf.origin[0], hf.origin[1]
    out = np.full(len(x), -np.inf)
    for s in _chunks(len(x), len(az) * len(t)):
        px = x[s, None, None] + dirs[None, :, 0, None] * t
        py = y[s, None, None] + dirs[None, :, 1, None] * t
        inside = (px >= ox) & (px <= ox + w) & (py >= oy) & (py <= oy + d)
        need = hf.ground_height(px, py) - t * np.tan(rise_rad)
        out[s] = np.median(np.where(inside, need, -np.inf).max(axis=2), axis=1)
    return out
