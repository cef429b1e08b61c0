"""The terrain's one restricted quadtree of tilelets: saturated node errors and bounding boxes, per tile on the GPU.

Every tile of every pyramid level is a part of one quadtree over the level-0 samples (the pyramid subsamples,
so a level-l tile's tilelets are the level-0 quadtree's nodes of 2^(l+1) cells and up). Its error pyramid is
computed once over the whole padded grid (``raster.quadtree.error_pyramid``), so the effective errors are
saturated across tile borders: a node's effective error is at least 1/beta times that of its children and of
the child-size nodes touching its edges from outside, wherever they lie.

A node of side s splits when ``E * K / d > tau``: E its effective error (metres), K the view's pixels per
radian, d the distance from the eye to the node's box. The box is the node's square grown by s on every side,
with the height range of the samples under it; the boxes are nested along every dependency (a child's and an
outside neighbour-child's box lie inside the parent's), so d never grows from a node to the nodes whose split
it must follow, and every node decides alone, on the GPU, with a crack-free (restricted) result.

Per tile the GPU holds, for each local level m (node side 2^(m+1) tile cells), a grid of the tile's nodes with
a one-node apron on every side: (E, zlo, zhi, inside) float32, zlo/zhi relative to the terrain origin z.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from hybrid.terrain.stored import StoredTerrain
from hybrid.tiles.fans import grow3 as _grow
from hybrid.tiles.pyramid import TilePyramid

from .quadtree import GPU_BETA, error_pyramid

_CACHE: dict = {}


@dataclass(frozen=True)
class GlobalNodes:
    """Saturated effective errors and box height ranges of every node of the whole padded grid, by global level.

    Global level g: nodes of 2^(g+1) level-0 cells; arrays (R >> (g+1))², row from the south. zlo/zhi span the
    samples of the node's box (its square grown by its side on every side), relative to the terrain origin z.
    """

    cells: int
    beta: float
    effective: tuple
    zlo: tuple
    zhi: tuple


def global_nodes(hf, tile_size: int, beta: float = GPU_BETA) -> GlobalNodes:
    """The whole grid's node errors and boxes, over the pyramid's padded grid (cached per height field,
    tile size and beta: about 2.5 s for 1025² samples)."""
    key = (id(hf), int(tile_size), float(beta))
    hit = _CACHE.get(key)
    if hit is not None and hit[0]() is hf:
        return hit[1]
    grid = hf.load() if isinstance(hf, StoredTerrain) else hf     # a tile store small enough to hold (else refused)
    pyramid = TilePyramid(grid, tile_size)
    pyr = error_pyramid(pyramid.padded, beta)
    zlo = tuple(_grow(z, np.minimum).astype(np.float32) for z in pyr.zmin)
    zhi = tuple(_grow(z, np.maximum).astype(np.float32) for z in pyr.zmax)
    nodes = GlobalNodes(pyr.n, float(beta), tuple(e.astype(np.float32) for e in pyr.effective), zlo, zhi)
    ref = weakref.ref(hf, lambda _r, k=key: _CACHE.pop(k, None))
    _CACHE[key] = (ref, nodes)
    return nodes


def tile_levels(n: int) -> int:
    """Local levels of an n-cell tile's quadtree (0 .. log2(n) - 1)."""
    return int(np.log2(n))


def tile_node_block(nodes: GlobalNodes, level: int, tx: int, ty: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(data (count, 4) float32, offsets (levels + 1,) int32): the tile's nodes with a one-node apron, per local
    level m row by row from the south; columns E, zlo, zhi, inside (0 outside the grid)."""
    blocks, offsets = [], [0]
    for m in range(tile_levels(n)):
        g = level + m
        side = n >> (m + 1)
        E, lo, hi = nodes.effective[g], nodes.zlo[g], nodes.zhi[g]
        total = E.shape[0]
        rows = ty * side + np.arange(-1, side + 1)
        cols = tx * side + np.arange(-1, side + 1)
        inside = ((rows >= 0) & (rows < total))[:, None] & ((cols >= 0) & (cols < total))[None, :]
        r = np.clip(rows, 0, total - 1)[:, None]
        c = np.clip(cols, 0, total - 1)[None, :]
        block = np.stack([E[r, c], lo[r, c], hi[r, c], inside.astype(np.float32)], axis=-1)
        block[~inside] = (0.0, 0.0, 0.0, 0.0)
        blocks.append(block.reshape(-1, 4))
        offsets.append(offsets[-1] + (side + 2) ** 2)
    return np.ascontiguousarray(np.concatenate(blocks), dtype=np.float32), np.array(offsets, np.int32)
