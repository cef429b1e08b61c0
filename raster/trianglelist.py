"""Full-resolution baseline: every tile as an indexed triangle list of all its samples (VBO + IBO).

Each selected tile is drawn at its own level, unstitched by design; where neighbours differ in level, skirts
close the seam's T-junctions (raster.mesh_skirts). Cells are split along the (i, j) -> (i+1, j+1) diagonal like
the reference. Also builds the indexed list of exactly the triangles a tilelet set draws, for comparing the
geometry-shader path's throughput.
"""

from __future__ import annotations

import numpy as np

from hybrid.terrain.heightfield import spacing_pair

from .mesh_skirts import grid_border_edges
from .meshes import MeshStrategyBase


def grid_vertices(heights: np.ndarray, spacing) -> np.ndarray:
    """(rows*cols, 3) float32 tile-local positions (x east, y north metres; z metres) of all samples; spacing in
    metres, one number or an (x, y) pair (columns x apart, rows y apart)."""
    h = np.asarray(heights)
    sx, sy = spacing_pair(spacing, "grid")
    i, j = np.mgrid[0 : h.shape[0], 0 : h.shape[1]]
    return np.stack([j.ravel() * sx, i.ravel() * sy, h.ravel()], axis=1).astype(np.float32)


def grid_faces(rows: int, cols: int) -> np.ndarray:
    """(2*(rows-1)*(cols-1), 3) uint32 CCW triangles of a sample grid, SW-NE diagonal."""
    i, j = np.mgrid[0 : rows - 1, 0 : cols - 1]
    a = (i * cols + j).ravel().astype(np.uint32)
    b, c, d = a + 1, a + np.uint32(cols) + 1, a + np.uint32(cols)
    return np.stack([np.stack([a, b, c], 1), np.stack([a, c, d], 1)], axis=1).reshape(-1, 3)


def tilelet_faces(tset, n: int, stitching: bool = True) -> np.ndarray:
    """(t, 3) uint32 triangles (indices into the tile's (n+1)² sample grid) that a TileletSet draws, unmorphed."""
    lv = tset.leaves
    k = (1 << lv.level).astype(np.int64)
    cols = n + 1

    def post(c, r):
        return (lv.i0 + r * k) * cols + (lv.j0 + c * k)

    C = post(1, 1)
    ring = [post(0, 0), post(1, 0), post(2, 0), post(2, 1), post(2, 2), post(1, 2), post(0, 2), post(0, 1)]
    drop = tset.coarser if stitching else np.zeros(len(lv), np.int32)
    tris = []
    for side, bit in enumerate((4, 2, 8, 1)):  # S, E, N, W: ring indices 0-1-2, 2-3-4, 4-5-6, 6-7-0
        a, m, b = ring[2 * side], ring[2 * side + 1], ring[(2 * side + 2) % 8]
        d = (drop & bit) != 0
        tris.append(np.stack([C[d], a[d], b[d]], 1))
        tris.append(np.stack([C[~d], a[~d], m[~d]], 1))
        tris.append(np.stack([C[~d], m[~d], b[~d]], 1))
    return np.concatenate(tris).astype(np.uint32)


class TriangleListStrategy(MeshStrategyBase):
    """Draws every tile at full tile resolution from a VBO (12 bytes a sample) and an IBO (12 bytes a triangle)."""

    def mesh_of(self, tile):
        """All samples and 2 triangles a cell of the tile."""
        h = np.asarray(tile.heights)
        return grid_vertices(h, tile.spacing_xy), grid_faces(h.shape[0], h.shape[1])

    def border_edges(self, tile, vertices, faces):
        """The grid's outer rows and columns of samples, per side W, E, S, N."""
        h = np.asarray(tile.heights)
        return grid_border_edges(h.shape[0], h.shape[1])
