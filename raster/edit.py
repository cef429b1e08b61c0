"""The raster strategies following an edit: the terrain's node arrays, and which tiles read the nodes that changed.

An in-memory terrain's node arrays (``raster.nodes.global_nodes``, which every raster tile's upload and the
triangle estimate read) are updated in place over the nodes the edit reaches (``raster.node_edit``); the rect_nodes
state that takes is made at the terrain's first edit and kept per terrain, tile size and beta. A resident tile must
be uploaded again when its node block (its nodes and a one-node apron at each local level) meets the window of the
nodes whose values changed, or its own samples changed.
"""

from __future__ import annotations

import weakref

from hybrid.errors import TerrabenchError
from hybrid.terrain.edits import Window
from hybrid.terrain.stored import StoredTerrain

from .node_edit import NodeEdits, node_edits, update_nodes
from .nodes import global_nodes, tile_levels
from .quadtree import GPU_BETA

_STATE: dict = {}


def edit_state(hf, n: int, beta: float = GPU_BETA, side_errors: bool = True) -> NodeEdits:
    """The rect_nodes state of hf's node arrays for tiles of n cells (made on first use, kept while hf lives);
    ``side_errors`` as in ``raster.nodes.global_nodes``."""
    if isinstance(hf, StoredTerrain):
        raise TerrabenchError(
            f"{hf.name!r} is a tile store: its node arrays follow an edit through the in-memory "
            "copy the editor keeps (hybrid.editing.TerrainEditor), not here"
        )
    key = (id(hf), int(n), float(beta), bool(side_errors))
    hit = _STATE.get(key)
    if hit is not None and hit[0]() is hf:
        return hit[1]
    st = node_edits(hf, n, beta, side_errors)

    def drop(_ref, k=key) -> None:
        _STATE.pop(k, None)

    _STATE[key] = (weakref.ref(hf, drop), st)
    return st


def follow_nodes(hf, n: int, win: Window, beta: float = GPU_BETA, side_errors: bool = True) -> list[Window]:
    """Update hf's node arrays (tiles of n cells; ``side_errors`` as in ``global_nodes``) after the samples of
    ``win`` changed; per global level the window of the nodes whose values changed (node indices)."""
    st = edit_state(hf, n, beta, side_errors)
    return update_nodes(st, global_nodes(hf, n, beta, side_errors), hf, win)


def reads_changed_nodes(key, n: int, rewritten: list[Window]) -> bool:
    """Whether tile ``key``'s node block (n cells, local levels with a one-node apron) meets a window of changed
    nodes (per global level)."""
    for m in range(tile_levels(n)):
        g = key.level + m
        if g >= len(rewritten) or rewritten[g].empty:
            continue
        side = n >> (m + 1)
        r0, c0 = key.ty * side - 1, key.tx * side - 1
        w = rewritten[g]
        if r0 < w.i1 and w.i0 < r0 + side + 2 and c0 < w.j1 and w.j0 < c0 + side + 2:
            return True
    return False


def stale_tiles(change, resident) -> tuple[int, list]:
    """A raster strategy following an edit (``hybrid.contract.EditFollowing``, change a ``TerrainChange``):
    nothing in place; the resident tiles (key, GPU tile) whose samples or bounds changed or whose node block
    reads a changed node, for the renderer to upload again."""
    n, nodes = change.tile_size, list(change.nodes)
    return 0, [k for k, _ in resident if k in change.tiles or reads_changed_nodes(k, n, nodes)]
