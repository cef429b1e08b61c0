"""Terrains and views for the non-square ground spacing tests: one seeded 129² height grid under several spacings."""

from functools import cache

import numpy as np

from hybrid.camera.view import View
from hybrid.terrain.datasets import fbm
from hybrid.terrain.heightfield import HeightField

NON_SQUARE = ((30.0, 55.0), (55.0, 30.0))
SIZE = (320, 180)


@cache
def terrain(spacing: tuple[float, float]) -> HeightField:
    """The same 129² seeded fbm heights (0..800 m) with ground spacing (x, y) in metres, and a colour texture that
    ramps red from west to east and green from south to north (cell-centred)."""
    heights = fbm(size=129, amplitude=800.0, seed=3).heights
    i, j = np.mgrid[0:128, 0:128] + 0.5
    texture = np.stack([255 * j / 128, 255 * i / 128, np.full_like(i, 96.0)], axis=-1).round().astype(np.uint8)
    return HeightField(heights, spacing, name=f"fbm-{spacing[0]:g}x{spacing[1]:g}", texture=texture)


def views(hf: HeightField, width: int = SIZE[0], height: int = SIZE[1]) -> list[View]:
    """Four views placed by fractions of the terrain's extent: a high one from the south-west, low ones from the
    east, the north and the south-west looking across tile borders."""
    w, d = hf.extent
    ox, oy, oz = hf.origin
    lo, hi = hf.height_range
    size = max(w, d)
    c = np.array([ox + 0.5 * w, oy + 0.5 * d, oz + lo])
    out = [
        View(
            c + [-0.3 * w, -0.4 * d, hi - lo + 0.6 * size],
            c + [0.05 * w, 0.1 * d, 0.0],
            60,
            width,
            height,
            near=1.0,
            far=1e5,
        )
    ]
    for (fx, fy), lift, (tx, ty) in (((0.9, 0.4), 120.0, (0.1, 0.6)), ((0.35, 0.85), 150.0, (0.6, 0.1))):
        x, y = ox + fx * w, oy + fy * d
        z = float(hf.ground_height(x, y)) + lift
        out.append(View([x, y, z], [ox + tx * w, oy + ty * d, oz + lo], 60, width, height, near=1.0, far=1e5))
    x, y = ox + 0.2 * w, oy + 0.3 * d
    out.append(
        View([x, y, oz + hi + 100.0], [ox + 0.8 * w, oy + 0.75 * d, oz + lo], 60, width, height, near=1.0, far=1e5)
    )
    return out
