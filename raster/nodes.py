"""The terrain's one restricted quadtree of tilelets: saturated node errors and bounding boxes, per tile on the GPU.

Every tile of every pyramid level is a part of one quadtree over the level-0 samples (the pyramid subsamples,
so a level-l tile's tilelets are the level-0 quadtree's nodes of 2^(l+1) cells and up). Its error pyramid has
the values ``raster.quadtree.error_pyramid`` gives over the pyramid's whole padded square (``square_nodes``),
computed only at the nodes tiles read (``raster.rect_nodes``), so the effective errors are saturated across tile
borders: a node's effective error is at least 1/beta times that of its children and of
the child-size nodes touching its edges from outside, wherever they lie.

A node of side s splits when ``E * K / d > tau``: E its effective error (metres), K the view's pixels per
radian, d the distance from the eye to the node's box. The box is the node's square grown by s on every side,
with the height range of the samples under it; the boxes are nested along every dependency (a child's and an
outside neighbour-child's box lie inside the parent's), so d never grows from a node to the nodes whose split
it must follow, and every node decides alone, on the GPU, with a crack-free (restricted) result.

Per tile the GPU holds, for each local level m (node side 2^(m+1) tile cells), a grid of the tile's nodes with
a one-node apron on every side: (E, zlo, zhi, inside) float32, zlo/zhi relative to the terrain origin z, inside 0
beyond the node square, else 1 plus the node's four side-error codes (``hybrid.tiles.sidecodes.side_codes``): nodes split on their
full fans' errors and carry their stitched triangles' errors as codes (a store prepared before side errors holds
one error over both fans, and 1).

An in-memory height field gets its arrays from ``global_nodes``; a tile store has them on disk, written by
prepare (``hybrid.tiles.store_nodes``: the same values for nodes up to 1024 cells, an upper bound of the
effective error above; and ``hybrid.tiles.store_blocks``: each tile's block of them), and ``nodes_for`` hands
their Zarr arrays to ``tile_node_block``, which reads the tile's block (or one window per level of a store
without blocks), so the grid is never loaded. A periodic extension of a store serves arrays of the same shape
and slicing, computed window by window from its source's (``hybrid.tiles.periodic_nodes``: the source's values
away from the seams, never below the exact ones near them, where its nodes hold the combined form's bounds),
and its tiles' blocks are the source's blocks away from the seams (``hybrid.tiles.periodic_blocks``).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.stored import MAX_LOAD_SAMPLES, StoredTerrain
from hybrid.tiles.fans import grow3 as _grow
from hybrid.tiles.periodic_blocks import PeriodicBlocks
from hybrid.tiles.pyramid import TilePyramid
from hybrid.tiles.sidecodes import side_codes, stored_codes
from hybrid.tiles.store_blocks import block_offsets

from .quadtree import GPU_BETA, error_pyramid
from .rect_nodes import rect_nodes

_CACHE: dict[tuple, tuple[weakref.ref, GlobalNodes]] = {}


@dataclass(frozen=True)
class GlobalNodes:
    """Saturated effective errors and box height ranges of the padded square's nodes, by global level.

    Global level g: nodes of 2^(g+1) level-0 cells, row from the south; arrays of the level's first rows and
    columns: (R >> (g+1))² of a tile store's Zarr arrays or ``square_nodes``, or ``global_nodes``' (H_g, W_g),
    every node a tile reads (``raster.rect_nodes``). zlo/zhi span the samples of the node's box (its square grown
    by its side on every side), relative to the terrain origin z; cells is R, the padded square's cells a side.
    """

    cells: int
    beta: float
    effective: tuple
    zlo: tuple
    zhi: tuple
    blocks: Any = None  # a store's per-tile blocks, [level][ty, tx] (hybrid.tiles.store_blocks)
    sides: tuple | None = None  # the blocks' fourth column per level (``side_codes``); None: 1 (a store
    # prepared before side errors: one error over both fans)


def square_nodes(hf, tile_size: int, beta: float = GPU_BETA, side_errors: bool = True) -> GlobalNodes:
    """Node arrays over the pyramid's whole padded square ((R >> (g+1))² per level), as ``error_pyramid`` gives
    them: the reference ``global_nodes`` and the tile store's builds are checked against (R² memory: small
    grids only); ``side_errors`` as in ``global_nodes``."""
    grid = hf.load() if isinstance(hf, StoredTerrain) else hf
    pyramid = TilePyramid(grid, tile_size)
    pyr = error_pyramid(pyramid.padded, beta, side_errors)
    zlo = tuple(_grow(z, np.minimum).astype(np.float32) for z in pyr.zmin)
    zhi = tuple(_grow(z, np.maximum).astype(np.float32) for z in pyr.zmax)
    effective = tuple(e.astype(np.float32) for e in pyr.effective)
    sides = (
        tuple(
            side_codes(d, e, effective[g + 1] if g + 1 < len(effective) else None)
            for g, (d, e) in enumerate(zip(pyr.sides, effective))
        )
        if side_errors
        else None
    )
    return GlobalNodes(pyr.n, float(beta), effective, zlo, zhi, sides=sides)


def global_nodes(hf, tile_size: int, beta: float = GPU_BETA, side_errors: bool = True) -> GlobalNodes:
    """The node arrays every tile of hf's pyramid reads (``raster.rect_nodes``: over the grid's rectangle of
    tiles at each level and their aprons, memory following the grid's samples; cached per height field, tile
    size, beta and form); ``side_errors``: split on the full fans' errors with side codes (``raster.quadtree``),
    else both fans in one error (the combined form: a store prepared before side codes holds it, a periodic
    extension's nodes near its seams take bounds of it)."""
    key = (id(hf), int(tile_size), float(beta), bool(side_errors))
    hit = _CACHE.get(key)
    if hit is not None and hit[0]() is hf:
        return hit[1]
    grid = hf.load() if isinstance(hf, StoredTerrain) else hf  # a store without usable node arrays, if it fits
    R, effective, zlo, zhi, sides = rect_nodes(grid, int(tile_size), float(beta), bool(side_errors))
    nodes = GlobalNodes(R, float(beta), effective, zlo, zhi, sides=sides)
    ref = weakref.ref(hf, lambda _r: _CACHE.pop(key, None))  # key is never rebound
    _CACHE[key] = (ref, nodes)
    return nodes


def nodes_for(hf, tile_size: int, beta: float = GPU_BETA) -> GlobalNodes:
    """The nodes the tiles of hf read: a tile store's node arrays (Zarr, or a periodic extension's served from its
    source's, read a tile's window at a time) when it has them for this tile size and beta, else ``global_nodes``
    (a store prepared without them is refused; a periodic extension of one is loaded whole if small enough)."""
    if not isinstance(hf, StoredTerrain):
        return global_nodes(hf, tile_size, beta)
    periodic = hf.store.attrs.get("periodic")
    path = periodic["source"] if periodic else hf.path  # the store that prepare writes
    small = hf.rows * hf.cols <= MAX_LOAD_SAMPLES
    info = hf.store.attrs.get("nodes")
    if not info:
        if periodic and small:
            return global_nodes(hf, tile_size, beta)
        raise TerrabenchError(
            f"{path}: this tile store was prepared without the raster strategies' node arrays; run terrabench "
            f"prepare again on the same input with --out {path} to add them (the ray caster draws it as it is)"
        )
    if int(tile_size) != int(hf.store.attrs["tile_size"]) or float(beta) != float(info["beta"]):
        if not small:
            raise TerrabenchError(
                f"{path}: node arrays were prepared for tiles of {hf.store.attrs['tile_size']} "
                f"and beta {info['beta']}, not {tile_size} and {beta}; the grid is too large to "
                "build them in memory"
            )
        return global_nodes(hf, tile_size, beta)
    key = (id(hf), int(tile_size), float(beta))
    hit = _CACHE.get(key)
    if hit is not None and hit[0]() is hf:
        return hit[1]
    levels = range(int(info["levels"]))
    g = hf.store
    effective, zlo, zhi = (tuple(g[f"nodes/{k}/{lev}"] for lev in levels) for k in ("effective", "zlo", "zhi"))
    arrays = (effective, zlo, zhi)
    codes = stored_codes(g, len(levels))
    blocks: PeriodicBlocks | tuple | None = None
    if hf.store.attrs.get("node_blocks"):
        tiers = range(int(hf.store.attrs["max_level"]) + 1)
        if periodic:  # the source's blocks away from the seams, cut near them
            src, src_levels = g.source, range(int(g.source.attrs["max_level"]) + 1)
            blocks = PeriodicBlocks(
                tuple(src[f"nodes/blocks/{lev}"] for lev in src_levels),
                arrays,
                int(tile_size),
                int(periodic["period_cells"]),
                int(periodic["size"]) - 1,
                len(tiers),
                codes,
            )
        else:
            blocks = tuple(g[f"nodes/blocks/{lev}"] for lev in tiers)
    nodes = GlobalNodes(int(info["square"]), float(beta), effective, zlo, zhi, blocks, codes)
    _CACHE[key] = (weakref.ref(hf, lambda _r: _CACHE.pop(key, None)), nodes)  # key is never rebound
    return nodes


def pending_cut(hf, n: int, beta: float, key):
    """The slow part of reading tile ``key``'s node block as a callable a loader thread can run ahead (cutting a
    periodic extension's block near a seam from its node arrays), or None where the block is one read."""
    if (
        not isinstance(hf, StoredTerrain)
        or not hf.store.attrs.get("periodic")
        or not hf.store.attrs.get("node_blocks")
        or int(hf.store.attrs["tile_size"]) != int(n)
    ):
        return None
    blocks = nodes_for(hf, n, beta).blocks
    if not isinstance(blocks, PeriodicBlocks) or blocks.ready(key.level, key.tx, key.ty):
        return None
    level, tx, ty = int(key.level), int(key.tx), int(key.ty)
    return lambda: blocks[level][ty, tx]


def tile_levels(n: int) -> int:
    """Local levels of an n-cell tile's quadtree (0 .. log2(n) - 1)."""
    return int(np.log2(n))


def tile_node_block(nodes: GlobalNodes, level: int, tx: int, ty: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(data (count, 4) float32, offsets (levels + 1,) int32): the tile's nodes with a one-node apron, per local
    level m row by row from the south; columns E, zlo, zhi, inside (0 outside the grid). One read of the
    store's block where it has them, else one window of each level (numpy or Zarr arrays alike)."""
    if nodes.blocks is not None:
        data = np.asarray(nodes.blocks[level][ty, tx], dtype=np.float32)
    else:
        data = _cut(nodes, level, tx, ty, n)
    return np.ascontiguousarray(data), block_offsets(n)


def _cut(nodes: GlobalNodes, level: int, tx: int, ty: int, n: int) -> np.ndarray:
    """A tile's block (nodes, 4) float32 cut from node arrays by global level that hold a level's first rows and
    columns (the whole square's, or ``global_nodes``' prefix of every node a tile reads): zeros beyond them, as
    beyond the square (``hybrid.tiles.store_blocks.band_blocks``' layout)."""
    parts = []
    for m in range(tile_levels(n)):
        g, side = level + m, n >> (m + 1)
        rows, cols = nodes.effective[g].shape
        r0, c0 = ty * side - 1, tx * side - 1
        ra, rb, ca, cb = max(r0, 0), min(r0 + side + 2, rows), max(c0, 0), min(c0 + side + 2, cols)
        block = np.zeros((side + 2, side + 2, 4), np.float32)
        if rb > ra and cb > ca:
            at = (slice(ra - r0, rb - r0), slice(ca - c0, cb - c0))
            for k, arr in enumerate((nodes.effective[g], nodes.zlo[g], nodes.zhi[g])):
                block[at + (k,)] = np.asarray(arr[ra:rb, ca:cb])
            block[at + (3,)] = 1.0 if nodes.sides is None else np.asarray(nodes.sides[g][ra:rb, ca:cb])
        parts.append(block.reshape(-1, 4))
    return np.concatenate(parts)
