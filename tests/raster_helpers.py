"""Helpers shared by the raster tests: views along tile borders and across level transitions, hole counts."""

import numpy as np

from hybrid.camera.view import View


def border_views(hf, width=320, height=180):
    """Low and high views along tile borders (x = 64, 128 cells; y = 64 cells) and one diagonal view."""
    w, d = hf.extent
    ox, oy, oz = hf.origin
    lo, hi = hf.height_range
    out = []
    for bxi, zf, ty in ((128, 0.15, 0.9), (64, 0.4, 0.6), (128, 1.0, 0.5)):
        bx = ox + bxi * hf.spacing_x
        eye = np.array([bx, oy - 0.05 * d, oz + hi + zf * (hi - lo) + 50])
        out.append(View(eye, np.array([bx, oy + ty * d, oz + lo]), 60, width, height, near=1.0, far=10 * w))
    eye = np.array([ox + 0.1 * w, oy + 0.1 * d, oz + hi + 100])
    out.append(View(eye, np.array([ox + 0.7 * w, oy + 0.7 * d, oz + lo]), 60, width, height, near=1.0, far=10 * w))
    by = oy + 64 * hf.spacing_y
    eye = np.array([ox - 0.05 * w, by, oz + hi + 0.3 * (hi - lo) + 50])
    out.append(View(eye, np.array([ox + 0.8 * w, by, oz + lo]), 60, width, height, near=1.0, far=10 * w))
    return out


def holes(result, reference, view, hf) -> int:
    """Pixels without terrain that have terrain above them in their column where the reference has terrain.

    Pixels whose reference hit lies within one cell of the terrain's outer boundary are not counted: there
    the terrain's side silhouette itself differs with the level of detail (no crack can be there).
    """
    m = result.mask
    above = np.zeros_like(m)
    above[1:] = np.maximum.accumulate(m, axis=0)[:-1]
    ys, xs = np.nonzero(~m & reference.mask & above)
    if ys.size == 0:
        return 0
    p = view.eye + view.pixel_rays(ys, xs) * reference.distance[ys, xs, None]
    c = (p[:, :2] - np.array(hf.origin[:2])) / np.array([hf.spacing_x, hf.spacing_y])
    inner = (c[:, 0] > 1) & (c[:, 1] > 1) & (c[:, 0] < hf.cols - 2) & (c[:, 1] < hf.rows - 2)
    return int(inner.sum())
