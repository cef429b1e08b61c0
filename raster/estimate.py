"""Triangles the tilelet strategy draws for a tile at a view, estimated on the CPU from node errors (no GL).

The GPU selection splits a node when ``E * K / tau > d``, with d the distance from the eye to that node's own
box, so the far part of a near tile is coarser than its near edge. The estimate follows it at two grains: a
tile's small nodes are counted against the distance of the block of the tile they lie in (4 x 4 blocks a
tile), its few large ones each against its own box (grown by its side, as the GPU's), and the tile's root
always splits (the tile tree refined it). The share of the splits in blocks (and large nodes) that reach into
the view frustum estimates what is left after the GPU's tilelet culling. Per tile the node errors, blocks and
boxes are built once, the small nodes' errors as tables of split counts by threshold (errors rounded to the
nearest of 32 bins an octave: on Puget's flights, tiles of 64-256 cells, 90 % of tiles within 3 % of the exact
count, the median equal, frames within 1.5 %; a look-up each, where a binary search among the sorted errors
missed the cache at nearly every step); a frame's tiles are then estimated together in a handful of array operations.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from hybrid.camera.view import View
from hybrid.contract import DEFAULT_FULL_RES
from hybrid.errors import TerrabenchError
from hybrid.terrain.stored import StoredTerrain
from hybrid.tiles.pyramid import TileKey, TilePyramid
from hybrid.tiles.sidecodes import decoded_sides, holds_side_codes, per_child
from hybrid.tiles.tiletree import SelectedTile

from .nodes import nodes_for, pending_cut, tile_node_block
from .split_tables import TABLE_BINS, SplitTables, kind_splits, split_tables
from .quadtree import GPU_BETA, check_full_res, error_pyramid

BLOCKS = 4                      # blocks a tile side for the small nodes' distances
MAX_TILES = 4096                # tiles whose TileNodes are kept (least recently used first out)
NEAR_TRIANGLES = 7              # a lean leaf near its split draws this many more than 4 (fitted to Puget flights:
                                # 0.86-1.31x the drawn count a frame; 8 if no neighbour shared its midpoints)
NEAR_SIDE_TRIANGLES = 1.5       # with side errors: a leaf side near its midpoint's need draws 1 (own) to 2 (and the
SPLIT1_TRIANGLES = 8            # neighbour's) more, and a split level-1 node of a full-resolution tile 4 leaves that
                                # keep their midpoints; both fitted to Puget's flyover, orbit and dolly (tiles of
                                # 128, 320x180, 2/3 px, eight views): 0.98-1.14x the drawn count a frame, per-tile
                                # median 0.98x (coarser levels' tiles 0.95x)


@dataclass(frozen=True)
class TileNodes:
    """What the estimate needs of one tile's quadtree (metres, world frame): errors and where the nodes are.

    fine: effective errors of the nodes no larger than a block, one row per block (row-major, BLOCKS² blocks;
    every block holds as many); lean: the same with the level-0 nodes (which never split, but keep their edge
    midpoints near their own split), but 0 in a full-resolution tile, whose level-0 leaves keep every midpoint;
    split1: there, the level-1 nodes' errors (a split one makes four such leaves), else zeros; coarse_error: the
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


def tile_nodes(tile, beta: float = GPU_BETA, full_res: bool = False) -> TileNodes:
    """The estimate's data of one pyramid tile (``hybrid.tiles.pyramid.Tile``: heights, origin, spacing), from
    its own heights' error pyramid in the combined form (both fans in one error: the tiles built this way are a
    store's prepared before side errors); ``full_res``: a level-0 tile."""
    pyr = error_pyramid(tile.heights, beta, side_errors=False)
    return _tile_nodes(pyr.effective, pyr.zmin, pyr.zmax, tile.n, tile.origin, (tile.spacing_x, tile.spacing_y),
                       full_res)


def block_tile_nodes(data: np.ndarray, offsets: np.ndarray, n: int, origin, spacing,
                     full_res: bool = False, beta: float = GPU_BETA) -> TileNodes:
    """The estimate's data of an n-cell tile at world ``origin`` with ``spacing`` (x, y) metres, from its node
    block (``raster.nodes.tile_node_block``): the saturated errors and grown box ranges the GPU selection reads
    (from a tile store, one read and no error pyramid)."""
    grids = [data[offsets[m]:offsets[m + 1]].reshape((n >> (m + 1)) + 2, (n >> (m + 1)) + 2, 4)[1:-1, 1:-1]
             for m in range(len(offsets) - 1)]
    effective = [g[..., 0].astype(np.float64) for g in grids]
    sides = None
    if any(np.any(g[..., 3] > 1.0) for g in grids):          # side codes (``hybrid.tiles.sidecodes``)
        parents = [data[offsets[m + 1]:offsets[m + 2]].reshape((n >> (m + 2)) + 2, -1, 4)[1:-1, 1:-1, 0]
                   if m + 1 < len(grids) else None for m in range(len(grids))]
        sides = [decoded_sides(g[..., 3], p) for g, p in zip(grids, parents)]
    return _tile_nodes(effective, [g[..., 1] for g in grids], [g[..., 2] for g in grids], n, origin, spacing,
                       full_res, sides, beta)


def _tile_nodes(effective, zmin, zmax, n: int, origin, spacing, full_res: bool = False, sides=None,
                beta: float = GPU_BETA) -> TileNodes:
    """TileNodes from per local level effective errors, height ranges (metres above the origin z) and, where the
    nodes have them, side errors ((4, ...) per level, metres, at least the effective error)."""
    top = len(effective) - 1
    nb = max(1, min(BLOCKS, n // 8))
    cells = n // nb                                              # block side, tile cells
    org = np.asarray(origin, dtype=np.float64)
    sp = np.asarray(spacing, dtype=np.float64)
    fine, coarse_e, coarse_lo, coarse_hi = [np.zeros((nb * nb, 0))], [], [], []
    for m in range(0, top):
        side = 2 << m                                            # node side, tile cells
        e = effective[m]
        a, b = np.indices(e.shape)
        if side <= cells:                                        # (block, node in block): blocks hold equal shares
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
    lean = np.concatenate([np.zeros_like(level0) if full_res else level0, above], axis=1)   # errors 0 never count
    split1 = level1 if full_res else np.zeros_like(level1)
    if sides is not None:
        lean = _lean_sides(effective, sides, len(fine) - 1, nb, beta)
        if full_res:                                             # level-0 leaves keep every midpoint: split1's
            lean[:, :4 * level0.shape[1]] = 0.0
    return TileNodes(above, lean, split1, cat(coarse_e, np.float64),
                     np.concatenate([block_lo, cat(coarse_lo, np.float64, 3)]),
                     np.concatenate([block_hi, cat(coarse_hi, np.float64, 3)]), int(top >= 1),
                     1 if sides is None else 4)


def _lean_sides(effective, sides, levels: int, nb: int, beta: float) -> np.ndarray:
    """(blocks, 4 x small nodes) of min(side error, beta E of the parent) for the small levels 0 .. levels-1."""
    out = []
    for m in range(levels):
        parent = effective[m + 1] if m + 1 < len(effective) else np.full((1, 1), np.inf)
        v = np.minimum(sides[m], beta * per_child(parent))
        v[np.isinf(v)] = 0.0                                     # a tile's root: split by the tile tree
        per = v.shape[1] // nb
        out.append(v.reshape(4, nb, per, nb, per).transpose(1, 3, 0, 2, 4).reshape(nb * nb, -1))
    return np.concatenate(out, axis=1)


KINDS = ("fine", "lean", "split1")   # the small-node error sets a tile keeps (``TileNodes`` fields), one table each


def estimate_rows(tables: SplitTables, rows: np.ndarray, coarse: np.ndarray, boxes: np.ndarray, root: np.ndarray, eye,
                  k_tau: float, planes=None, inside=None, lean: bool = True,
                  beta: float = GPU_BETA, sides=1) -> tuple[np.ndarray, np.ndarray]:
    """(triangles (B,), visible share (B,)) of B tiles' quadtrees for an eye (world metres) and K / tau (pixels per
    radian over tau), and the share in [0, 1] of their splits in blocks or large nodes inside the frustum
    ``planes`` (eye-relative, as View's; None: all). Without ``lean``: 8 triangles a leaf (a split adds 3
    leaves). With it (the small nodes' lean tables, level 0 included), as lean leaves draw: 4 a leaf, and
    ``NEAR_TRIANGLES`` more for each leaf near its own split (its tolerance below E / beta): it keeps its edge
    midpoints, each a triangle on both sides, and near leaves lie together, sharing some; the split1 tables count
    full-resolution tiles' split level-1 nodes, whose four leaves draw 8 each. Rows whose nodes have side errors
    (``sides`` (B,) 4, else 1) count their leaves' near sides instead, ``NEAR_SIDE_TRIANGLES`` each, and a split
    level-1 node of a full-resolution tile ``SPLIT1_TRIANGLES``.

    The tiles are rows of stacked ``TileNodes``: ``tables`` the small nodes' ``split_tables`` of every kind, of
    which ``rows`` (B,) are the tiles'; coarse (B, C) errors; boxes (B, 6, blocks + C) as (hi, lo) corners in world
    metres, coordinates first; root (B,). ``inside`` (B,) marks tiles wholly inside the frustum, whose boxes need
    no test. A node splits when E * k_tau exceeds its block's (or, large, its own box's) distance: a block's count
    of each kind is one look-up in its table, errors rounded to 1/32 octave (``split_tables``)."""
    b, nb = len(rows), tables.blocks
    if not b:
        return np.zeros(0, np.int64), np.zeros(0)
    eye = np.asarray(eye, dtype=np.float64)
    e = eye[:, None]
    d = np.maximum(np.maximum(boxes[:, 3:] - e, e - boxes[:, :3]), 0.0)            # (B, 3, boxes) per axis
    d = np.sqrt(np.einsum("bkn,bkn->bn", d, d))                                     # (B, boxes) metres
    counts = kind_splits(tables, rows, d[:, None, :nb] * (np.array([1.0, beta, 1.0]) / k_tau)[:, None])
    large = coarse * k_tau > d[:, nb:]
    per_box = np.concatenate([counts[:, 0], large], axis=1)                        # splits in each box (B, boxes)
    splits = per_box.sum(axis=1)
    if planes is None:
        shown = splits
    else:                          # a box is outside when its corner farthest along some plane's normal is behind it
        w, bias = _corner_test(planes, eye)
        seen = (w.T @ boxes.transpose(1, 0, 2).reshape(6, -1) >= bias[:, None]).all(axis=0).reshape(b, -1)
        if inside is not None:
            seen |= np.asarray(inside, bool)[:, None]
        shown = np.einsum("bn,bn->b", per_box, seen)
    leaves = 1 + 3 * (splits + root)
    visible = np.minimum(1.0, (1 + 3 * (shown + root)) / leaves)
    if not lean:
        return 8 * leaves, visible
    per_kind = counts[:, 1:].sum(axis=2)
    near = per_kind[:, 0] / sides - splits + (coarse * (k_tau / beta) > d[:, nb:]).sum(axis=1)   # near leaves
    weight = np.where(np.asarray(sides) == 4, 4 * NEAR_SIDE_TRIANGLES, NEAR_TRIANGLES)
    # a split level-1 node of a full-resolution tile: four leaves that keep their midpoints, four more each (fitted
    # with side errors)
    split1 = np.where(np.asarray(sides) == 4, SPLIT1_TRIANGLES, 16)
    return np.rint(4 * leaves + weight * near + split1 * per_kind[:, 1]).astype(np.int64), visible


def _corner_test(planes: np.ndarray, eye: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(6, 6) weights and (6,) bounds such that a (hi, lo) world box row r lies wholly behind some frustum plane
    (eye-relative ``planes``) exactly where some column of r @ weights falls below its bound: per plane, its
    corner farthest along the normal."""
    n = planes[:, :3].T
    return np.concatenate([np.maximum(n, 0.0), np.minimum(n, 0.0)]), eye @ n - planes[:, 3]


class _Rows:
    """Many tiles' TileNodes as stacked arrays, one row per tile, so a frame's tiles are gathered in one
    indexing per field; beyond ``limit`` tiles the least recently used row is reused (never one of the call at
    hand: ``lookup`` stamps its rows with the call's tick)."""

    FIELDS = ("coarse_error", "boxes", "root", "sides")     # as TileNodes has them; the small nodes' errors of
                                                    # KINDS as ``split_tables`` in ``tables``

    def __init__(self, limit: int):
        self.limit, self.row = limit, {}                       # key -> row
        self.keys: list = []                                   # row -> key
        self.arrays: dict = {}                                 # FIELDS, (rows, ...) each
        self.tables: SplitTables | None = None
        self.stamp = np.zeros(0, np.int64)                     # row -> tick of its last use
        self.tick = 0

    def lookup(self, keys) -> np.ndarray:
        """(len(keys),) rows of the keys, -1 where not stored; the stored ones are now the most recently used."""
        self.tick += 1
        get = self.row.get
        rows = np.array([get(k, -1) for k in keys], dtype=np.int64)
        self.stamp[rows[rows >= 0]] = self.tick
        return rows

    def put(self, key, nodes: TileNodes) -> int:
        """Store a tile's nodes as used by the call at hand; returns its row."""
        if len(self.row) >= self.limit:
            r = int(self.stamp[:len(self.keys)].argmin())      # the least recently used
            del self.row[self.keys[r]]
            self.keys[r] = key
        else:
            r = len(self.keys)
            self.keys.append(key)
            if r >= len(self.stamp):
                self._grow(nodes)
        self.tables.base[r], self.tables.tables[r] = split_tables([getattr(nodes, kind) for kind in KINDS])
        for f in self.FIELDS:
            self.arrays[f][r] = getattr(nodes, f)
        self.stamp[r] = self.tick
        self.row[key] = r
        return r

    def _grow(self, nodes: TileNodes) -> None:
        """Double the rows (at least 16, at most ``limit``); rows not yet filled count no splits."""
        cap = len(self.stamp)
        new = min(max(2 * cap, 16), self.limit)          # the call's own rows fit: limit >= its tiles
        vals = {f: np.asarray(getattr(nodes, f)) for f in self.FIELDS}
        grown = {f: np.zeros((new, *v.shape), v.dtype if f not in ("root", "sides") else np.int64)
                 for f, v in vals.items()}
        most = max(getattr(nodes, kind).shape[1] for kind in KINDS)       # a block's nodes of one kind
        tables = SplitTables(np.zeros(new, np.int64), np.zeros((new, len(KINDS), nodes.fine.shape[0], TABLE_BINS),
                                                               np.uint16 if most < 1 << 16 else np.uint32))
        if self.arrays:
            for f in grown:
                grown[f][:cap] = self.arrays[f]
            tables.base[:cap], tables.tables[:cap] = self.tables.base, self.tables.tables
        self.arrays, self.tables = grown, tables
        self.stamp = np.concatenate([self.stamp, np.zeros(new - cap, np.int64)])


class TileletTriangleEstimator:
    """A ``hybrid.contract.TriangleEstimator`` for the tilelet strategy over one tile pyramid.

    Per tile, its ``TileNodes`` are built once; ``build_ms`` adds up the wall time spent building them: one-time
    work per tile, which renderers count apart from planning. With ``background`` (a store's loader thread cuts
    blocks), a tile whose node block still needs cutting is left unknown (NaN) rather than cut in the caller's
    thread, and the cut is in ``waiting`` for the loader to run. ``full_res``: the strategies' full-resolution rule
    (hybrid.contract.FULL_RES; "lean": level-0 tiles' leaves counted as every other tile's).
    """

    def __init__(self, pyramid: TilePyramid, beta: float = GPU_BETA, lean: bool = True,
                 full_res: str = DEFAULT_FULL_RES):
        self.pyramid = pyramid
        self.beta, self.lean, self.exact = float(beta), bool(lean), check_full_res(full_res) == "exact"
        self._rows = _Rows(MAX_TILES)
        self.build_ms, self.builds = 0.0, 0
        self.background = False
        self.waiting: dict = {}     # tiles of the last call left unknown for their block's cut -> the cut (callable)
        hf = pyramid.hf
        # a tile store whose nodes (as the GPU reads them) come in per-tile blocks: each tile's is one read, no
        # heights, no error pyramid (a periodic extension's near its seams is cut first, as the GPU's upload
        # cuts it); stores without them are not opened here (nodes_for may refuse or load them)
        self._blocks = None
        if isinstance(hf, StoredTerrain) and hf.store.attrs.get("node_blocks") and \
                int(hf.store.attrs["tile_size"]) == pyramid.n:
            nodes = nodes_for(hf, pyramid.n, beta)
            self._blocks = nodes if nodes.blocks is not None else None

    def _row(self, key: TileKey, deadline: float | None = None) -> int:
        """The new key's row, its nodes built first; -1 (not built) once ``deadline`` (perf_counter s) passed,
        or with ``background`` while its block waits to be cut (the cut then in ``waiting``)."""
        ready = self._block_ready(key)
        if ready is False and self.background:
            cut = pending_cut(self.pyramid.hf, self.pyramid.n, self.beta, key)
            if cut is not None:                                 # (None: the loader has just cut it)
                self.waiting[key] = cut
                return -1
        t0 = time.perf_counter()
        if deadline is not None and t0 >= deadline:
            return -1
        source = self._blocks if ready is not None else self._global_nodes()
        if source is not None:                                  # the block the GPU reads (cut here if need be)
            data, offsets = tile_node_block(source, key.level, key.tx, key.ty, self.pyramid.n)
            nodes = block_tile_nodes(data, offsets, self.pyramid.n, *self.pyramid.placement(key),
                                     self.exact and key.level == 0, self.beta)
        else:
            nodes = tile_nodes(self.pyramid.tile(key), self.beta, self.exact and key.level == 0)
        r = self._rows.put(key, nodes)
        self.builds += 1
        self.build_ms += (time.perf_counter() - t0) * 1e3
        return r

    def _global_nodes(self):
        """An in-memory height field's whole-grid nodes, which its GPU selection reads too (``nodes_for``, cached per
        height field): errors saturated across tile borders and, for a coarser pyramid level's tile, from the
        level-0 quadtree, where the tile's own heights' error pyramid misses what its neighbours and the finer data
        force (on Puget's orbit, level-1 tiles drew 1.09x the leaves and 1.14x the triangles that estimate
        counted); for a store without blocks, its node arrays read a tile's window at a time, as its GPU upload
        reads them; None (built from its heights then) for a store whose nodes hold the combined form (prepared
        before side codes), or whose node arrays do not serve this tile size."""
        hf = self.pyramid.hf
        if not isinstance(hf, StoredTerrain):
            return nodes_for(hf, self.pyramid.n, self.beta)
        if not holds_side_codes(hf.store):
            return None
        try:
            return nodes_for(hf, self.pyramid.n, self.beta)
        except TerrabenchError:
            return None

    def _block_ready(self, key: TileKey) -> bool | None:
        """Whether the tile's node block is one read (None: the store has no blocks; built from heights)."""
        if self._blocks is None:
            return None
        ready = getattr(self._blocks.blocks, "ready", None)
        return ready is None or ready(key.level, key.tx, key.ty)

    def _estimate(self, keys, view: View, tau: float, budget_ms: float | None = None,
                  inside=None) -> tuple[np.ndarray, np.ndarray]:
        self._rows.limit = max(self._rows.limit, len(keys))    # a frame's own rows are never reused for it
        deadline = None if budget_ms is None else time.perf_counter() + budget_ms / 1e3
        builds, self.waiting = self.builds, {}
        rows = self._rows.lookup(keys)
        for i in np.flatnonzero(rows < 0).tolist():
            rows[i] = self._row(keys[i], deadline)
        ok = rows >= 0
        if not ok.all():
            missing = [i for i in np.flatnonzero(~ok) if not self.background or self._block_ready(keys[i])]
            if missing and self.builds == builds:               # at least one build a call: the queue drains
                rows[missing[0]] = self._row(keys[missing[0]])  # (blocks left to cut: the loader's, not here)
                ok = rows >= 0
        a, r = self._rows.arrays, rows[ok]
        if not len(r):
            return np.full(len(rows), np.nan), np.full(len(rows), np.nan)
        est = estimate_rows(self._rows.tables, r, a["coarse_error"][r], a["boxes"][r], a["root"][r], view.eye,
                            float(view.pixels_per_radian) / tau, view.frustum_planes_rel(),
                            None if inside is None else inside[ok], self.lean, self.beta, a["sides"][r])
        if len(r) == len(rows):
            return est[0].astype(np.float64), est[1]
        tri, vis = np.full(len(rows), np.nan), np.full(len(rows), np.nan)
        tri[ok], vis[ok] = est
        return tri, vis

    def many(self, selected: list[SelectedTile], view: View, tau: float,
             budget_ms: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(triangles (B,) float, visible share (B,)) of the selected tiles at ``view`` for the bound tau (pixels).

        With ``budget_ms``, new tiles' nodes are built front to back only until that much wall time is spent (at
        least one a call); the tiles left get NaN for both (unknown this frame, built in a later one)."""
        return self._estimate([s.key for s in selected], view, tau, budget_ms, getattr(selected, "inside", None))

    def __call__(self, key: TileKey, selected: SelectedTile, view: View, tau: float) -> int:
        """Estimated triangles of tile ``key`` at ``view`` for the error bound tau (pixels)."""
        return int(self._estimate([key], view, tau)[0][0])
