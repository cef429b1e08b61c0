"""What the triangle estimate (``raster.estimate``) keeps of one tile's quadtree: its small nodes' errors by block,
its large nodes' errors and boxes, built once per tile from its heights or from the node block the GPU reads."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.tiles.sidecodes import decoded_sides, per_child

from .quadtree import GPU_BETA, error_pyramid

BLOCKS = 4  # blocks a tile side for the small nodes' distances


@dataclass(frozen=True)
class TileNodes:
    """What the estimate needs of one tile's quadtree (metres, world frame): errors and where the nodes are.

    fine: effective errors of the nodes no larger than a block, one row per block (row-major, BLOCKS² blocks;
    every block holds as many); lean: the same with the level-0 nodes (which never split, but keep their edge
    midpoints near their own split), but 0 in a full-resolution tile under the exact rule, whose level-0 leaves
    keep every midpoint; split1: in a full-resolution tile, the level-1 nodes' errors, else zeros; coarse_error: the
    larger nodes below the root; box_lo/hi: the blocks' boxes, then the larger nodes' grown boxes (BLOCKS² +
    coarse, 3); root: 1 where the tile's root can split. With side errors (``sides`` 4), lean holds each small
    node's four sides instead, as min(side error, beta times the parent's effective error), so that a side
    counts where its midpoint is near (side error above beta times the tolerance) and the parent splits (0 for a
    full-resolution tile's level 0, as above).
    """

    fine: np.ndarray
    lean: np.ndarray
    split1: np.ndarray
    coarse_error: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    root: int
    sides: int = 1

    @property
    def boxes(self) -> np.ndarray:
        """The boxes as (6, blocks + coarse): (hi, lo) corners' coordinates, as ``estimate_rows`` reads them."""
        return np.concatenate([self.box_hi, self.box_lo], axis=1).T


def tile_nodes(tile, beta: float = GPU_BETA, full_res: str | None = None) -> TileNodes:
    """The estimate's data of one pyramid tile (``hybrid.tiles.pyramid.Tile``: heights, origin, spacing), from
    its own heights' error pyramid in the combined form (both fans in one error: the tiles built this way are a
    store's prepared before side errors); ``full_res``: a level-0 tile's rule (hybrid.contract.FULL_RES)."""
    pyr = error_pyramid(tile.heights, beta, side_errors=False)
    return _tile_nodes(
        pyr.effective, pyr.zmin, pyr.zmax, tile.n, tile.origin, (tile.spacing_x, tile.spacing_y), full_res
    )


def block_tile_nodes(
    data: np.ndarray, offsets: np.ndarray, n: int, origin, spacing, full_res: str | None = None, beta: float = GPU_BETA
) -> TileNodes:
    """The estimate's data of an n-cell tile at world ``origin`` with ``spacing`` (x, y) metres, from its node
    block (``raster.nodes.tile_node_block``): the saturated errors and grown box ranges the GPU selection reads
    (from a tile store, one read and no error pyramid)."""
    grids = [
        data[offsets[m] : offsets[m + 1]].reshape((n >> (m + 1)) + 2, (n >> (m + 1)) + 2, 4)[1:-1, 1:-1]
        for m in range(len(offsets) - 1)
    ]
    effective = [g[..., 0].astype(np.float64) for g in grids]
    sides = None
    if any(np.any(g[..., 3] > 1.0) for g in grids):  # side codes (``hybrid.tiles.sidecodes``)
        parents = [
            data[offsets[m + 1] : offsets[m + 2]].reshape((n >> (m + 2)) + 2, -1, 4)[1:-1, 1:-1, 0]
            if m + 1 < len(grids)
            else None
            for m in range(len(grids))
        ]
        sides = [decoded_sides(g[..., 3], p) for g, p in zip(grids, parents)]
    return _tile_nodes(
        effective, [g[..., 1] for g in grids], [g[..., 2] for g in grids], n, origin, spacing, full_res, sides, beta
    )


def _tile_nodes(
    effective, zmin, zmax, n: int, origin, spacing, full_res: str | None = None, sides=None, beta: float = GPU_BETA
) -> TileNodes:
    """TileNodes from per local level effective errors, height ranges (metres above the origin z) and, where the
    nodes have them, side errors ((4, ...) per level, metres, at least the effective error)."""
    top = len(effective) - 1
    nb = max(1, min(BLOCKS, n // 8))
    cells = n // nb  # block side, tile cells
    org = np.asarray(origin, dtype=np.float64)
    sp = np.asarray(spacing, dtype=np.float64)
    fine, coarse_e, coarse_lo, coarse_hi = [np.zeros((nb * nb, 0))], [], [], []
    for m in range(top):
        side = 2 << m  # node side, tile cells
        e = effective[m]
        a, b = np.indices(e.shape)
        if side <= cells:  # (block, node in block): blocks hold equal shares
            per = cells // side
            fine.append(np.asarray(e, np.float64).reshape(nb, per, nb, per).transpose(0, 2, 1, 3).reshape(nb * nb, -1))
        else:
            lo_xy = org[:2] + np.stack([(b - 1) * side, (a - 1) * side], -1).reshape(-1, 2) * sp
            hi_xy = org[:2] + np.stack([(b + 2) * side, (a + 2) * side], -1).reshape(-1, 2) * sp
            coarse_e.append(e.ravel())
            coarse_lo.append(np.column_stack([lo_xy, org[2] + zmin[m].ravel()]))
            coarse_hi.append(np.column_stack([hi_xy, org[2] + zmax[m].ravel()]))
    by, bx = np.divmod(np.arange(nb * nb), nb)
    # block heights: the level-1 nodes' ranges reduced over each block (level 1 covers every sample)
    z1lo, z1hi = zmin[min(1, top)], zmax[min(1, top)]
    per = z1lo.shape[0] // nb
    zlo = z1lo.reshape(nb, per, nb, per).min(axis=(1, 3)).ravel()
    zhi = z1hi.reshape(nb, per, nb, per).max(axis=(1, 3)).ravel()
    block_lo = np.column_stack([org[0] + bx * cells * sp[0], org[1] + by * cells * sp[1], org[2] + zlo])
    block_hi = np.column_stack([org[0] + (bx + 1) * cells * sp[0], org[1] + (by + 1) * cells * sp[1], org[2] + zhi])

    def cat(parts, dtype, width=None):
        if parts:
            return np.concatenate(parts).astype(dtype)
        return np.zeros((0,) if width is None else (0, width), dtype)

    empty = np.zeros((nb * nb, 0))
    level0, rest = (fine[1], fine[2:]) if len(fine) > 1 else (empty, [])
    above = np.concatenate([empty, *rest], axis=1)
    level1 = rest[0] if rest else empty
    exact = full_res == "exact"
    lean = np.concatenate([np.zeros_like(level0) if exact else level0, above], axis=1)  # errors 0 never count
    split1 = level1 if full_res is not None else np.zeros_like(level1)
    if sides is not None:
        lean = _lean_sides(effective, sides, len(fine) - 1, nb, beta)
        if exact:  # level-0 leaves keep every midpoint: split1's
            lean[:, : 4 * level0.shape[1]] = 0.0
    return TileNodes(
        above,
        lean,
        split1,
        cat(coarse_e, np.float64),
        np.concatenate([block_lo, cat(coarse_lo, np.float64, 3)]),
        np.concatenate([block_hi, cat(coarse_hi, np.float64, 3)]),
        int(top >= 1),
        1 if sides is None else 4,
    )


def _lean_sides(effective, sides, levels: int, nb: int, beta: float) -> np.ndarray:
    """(blocks, 4 x small nodes) of min(side error, beta E of the parent) for the small levels 0 .. levels-1."""
    out = []
    for m in range(levels):
        parent = effective[m + 1] if m + 1 < len(effective) else np.full((1, 1), np.inf)
        v = np.minimum(sides[m], beta * per_child(parent))
        v[np.isinf(v)] = 0.0  # a tile's root: split by the tile tree
        per = v.shape[1] // nb
        out.append(v.reshape(4, nb, per, nb, per).transpose(1, 3, 0, 2, 4).reshape(nb * nb, -1))
    return np.concatenate(out, axis=1)


KINDS = ("fine", "lean", "split1")  # the small-node error sets a tile keeps (``TileNodes`` fields), one table each
