"""Errors of drawing full-resolution edge midpoints on their edges' lines (lean full-resolution leaves).

A level-0 leaf covers 2 x 2 cells drawn with the reference's SW-NE diagonals. Dropping the midpoint of one of
its edges puts that post on the line between the edge's ends and turns the diagonal of the two cells the
reference's diagonal runs through at that post (the cell south-west of it, the one north-east of it) to the fan's
NW-SE one. Both surfaces are linear on their common refinement, so they differ most at the midpoint (its
distance from the line) or at one of those two cells' centres (half the gap between the cell's two diagonals'
mid-heights): the larger of these is the drop's error, and the drawn surface stays that close to the
reference's everywhere, not just at samples. raster/select.comp.glsl computes the same from the tile heights.
"""
from __future__ import annotations

import numpy as np


def cell_gaps(h: np.ndarray) -> np.ndarray:
    """(n + 2)² metres: half the gap between each cell's two diagonals' mid-heights, cell (r, c) (south-west
    sample row r, column c) at [r + 1, c + 1], with a zero border for the cells beyond the tile."""
    g = 0.5 * np.abs(h[:-1, :-1] + h[1:, 1:] - h[1:, :-1] - h[:-1, 1:])
    return np.pad(g, 1)


def midpoint_errors(heights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ex, ey) metres for a tile's (n+1)² heights: ex[a, c] (n/2, n/2 + 1) for the midpoint (row 2a+1, column 2c)
    of the level-0 edge between units (a, c - 1) and (a, c); ey[r, b] (n/2 + 1, n/2) for the midpoint (2r, 2b+1)
    of the edge between units (r - 1, b) and (r, b): the larger of its distance from the edge's line and the
    gaps of the cells south-west and north-east of it (those inside the tile)."""
    h = np.asarray(heights, dtype=np.float64)
    G = cell_gaps(h)
    ex_dev = np.abs(h[1::2, ::2] - 0.5 * (h[:-1:2, ::2] + h[2::2, ::2]))
    ey_dev = np.abs(h[::2, 1::2] - 0.5 * (h[::2, :-1:2] + h[::2, 2::2]))
    # midpoint (r, c): the cell south-west of it is G[r, c], the one north-east G[r + 1, c + 1]
    ex = np.maximum(ex_dev, np.maximum(G[1:-1:2, :-1:2], G[2::2, 1::2]))
    ey = np.maximum(ey_dev, np.maximum(G[:-1:2, 1:-1:2], G[1::2, 2::2]))
    return ex, ey
