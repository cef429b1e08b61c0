"""Write the golden arrays of tests/test_golden.py: small fixed inputs and what the code computes from them.

Regenerate only on a deliberate change of the error pyramid, the leaf selection or the CPU ray caster, and
commit the new files with that change (test_golden.py checks each value independently as far as it can):

    PYTHONPATH=. python tests/golden/make_golden.py
"""

from pathlib import Path

import numpy as np

from raster.quadtree import error_pyramid, leaf_levels, leaves_from_levels
from raycast.cpu import cast_rays

HERE = Path(__file__).parent
LEAF_TOLERANCE = 4.0


def heights(n: int, seed: int) -> np.ndarray:
    """(n+1)² random whole-metre heights in [0, 20] (exact in float32), seeded."""
    return np.random.default_rng(seed).integers(0, 21, (n + 1, n + 1)).astype(np.float32)


def bump(n: int) -> np.ndarray:
    """(n+1)² whole-metre heights: a plane (exactly drawn by any leaf) with one steep bump near the
    south-west, so the leaves are fine there and coarse elsewhere."""
    i, j = np.mgrid[0 : n + 1, 0 : n + 1]
    return (j + 2 * i + np.floor(40 * np.exp(-((j - 8.0) ** 2 + (i - 11.0) ** 2) / 6.0))).astype(np.float32)


def rays() -> tuple[np.ndarray, np.ndarray]:
    """Origins and directions in texel space (x, y texels; z metres) over a 16-cell grid of 0..20 m heights:
    oblique in each quadrant, along +x and -y exactly, straight down, grazing, and one pointing up."""
    O = np.array(
        [
            [-2.0, -2.0, 30.0],
            [18.0, 3.0, 25.0],
            [5.0, 18.0, 28.0],
            [17.5, 17.5, 40.0],
            [-1.0, 7.5, 15.0],
            [9.25, 20.0, 12.0],
            [6.3, 4.7, 50.0],
            [0.5, 0.5, 10.0],
            [8.0, 8.0, 21.0],
        ]
    )
    D = np.array(
        [
            [1.0, 0.8, -2.5],
            [-1.0, 0.4, -0.7],
            [0.3, -1.0, -0.8],
            [-0.6, -0.7, -2.0],
            [1.0, 0.0, -0.05],
            [0.0, -1.0, -0.02],
            [0.0, 0.0, -1.0],
            [1.0, 1.0, 0.01],
            [0.2, 0.1, 1.0],
        ]
    )
    return O, D


def error_pyramid_case() -> dict:
    h = heights(8, seed=1)
    p = error_pyramid(h)
    return {
        "heights": h,
        **{f"errors{m}": p.errors[m] for m in range(p.top + 1)},
        **{f"effective{m}": p.effective[m] for m in range(p.top + 1)},
        **{f"sides{m}": p.sides[m] for m in range(p.top + 1)},
    }


def leaves_case() -> dict:
    h = bump(32)
    lv = leaves_from_levels(leaf_levels(error_pyramid(h), LEAF_TOLERANCE))
    return {"heights": h, "tolerance": np.float64(LEAF_TOLERANCE), "i0": lv.i0, "j0": lv.j0, "level": lv.level}


def rays_case() -> dict:
    h = heights(16, seed=3)
    O, D = rays()
    r = cast_rays(h, (16.0, 16.0), (float(h.min()), float(h.max())), O, D, reconstruction="triangles")
    return {"heights": h, "origin": O, "direction": D, "status": r.status, "point": r.point}


CASES = {"error_pyramid": error_pyramid_case, "leaves": leaves_case, "rays": rays_case}

if __name__ == "__main__":
    for name, make in CASES.items():
        np.savez_compressed(HERE / f"{name}.npz", **make())
        print(f"wrote {HERE / name}.npz")
