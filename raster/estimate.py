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
from collections.abc import Sequence
from functools import partial

import numpy as np

from hybrid.camera.view import View
from hybrid.contract import DEFAULT_FULL_RES
from hybrid.errors import TerrabenchError
from hybrid.terrain.stored import StoredTerrain
from hybrid.tiles.pyramid import TileKey, TilePyramid
from hybrid.tiles.sidecodes import holds_side_codes
from hybrid.tiles.tiletree import SelectedTile

from .edit import stale_tiles
from .nodes import nodes_for, tile_node_block
from .quadtree import GPU_BETA, check_full_res
from .split_tables import TABLE_BINS, SplitTables, split_tables
from .tile_nodes import KINDS, TileNodes, block_tile_nodes, tile_nodes

MAX_TILES = 4096  # tiles whose TileNodes are kept (least recently used first out)
NEAR_TRIANGLES = 7  # a lean leaf near its split draws this many more than 4 (fitted to Puget flights:
# 0.86-1.31x the drawn count a frame; 8 if no neighbour shared its midpoints)
NEAR_SIDE_TRIANGLES = 1.5  # with side errors: a leaf side near its midpoint's need draws 1 (own) to 2 (and the
SPLIT1_TRIANGLES = 8  # neighbour's) more, and a split level-1 node of a full-resolution tile 4 leaves that
# keep their midpoints; both fitted to Puget's flyover, orbit and dolly (tiles of
# 128, 320x180, 2/3 px, eight views): 0.98-1.14x the drawn count a frame, per-tile
# median 0.98x (coarser levels' tiles 0.95x). 8 below the 16 drawn: level-1 nodes
LEAN_SPLIT1_TRIANGLES = -8  # tested at their block's nearest distance split more often than drawn, in the lean
# rule too, whose split level-1 nodes add none (least squares over 24 such views at
# 2/3 and 2 px: -7.5; its full-resolution tiles' median error 0.16 -> 0.08)


def estimate_rows(
    tables: SplitTables,
    rows: np.ndarray,
    coarse: np.ndarray,
    boxes: np.ndarray,
    root: np.ndarray,
    eye,
    k_tau: float,
    planes=None,
    inside=None,
    lean: bool = True,
    beta: float = GPU_BETA,
    sides=1,
    split1_triangles=(SPLIT1_TRIANGLES, 16),
) -> tuple[np.ndarray, np.ndarray]:
    """(triangles (B,), visible share (B,)) of B tiles' quadtrees for an eye (world metres) and K / tau (pixels per
    radian over tau), and the share in [0, 1] of their splits in blocks or large nodes inside the frustum
    ``planes`` (eye-relative, as View's; None: all). Without ``lean``: 8 triangles a leaf (a split adds 3
    leaves). With it (the small nodes' lean tables, level 0 included), as lean leaves draw: 4 a leaf, and
    ``NEAR_TRIANGLES`` more for each leaf near its own split (its tolerance below E / beta): it keeps its edge
    midpoints, each a triangle on both sides, and near leaves lie together, sharing some; the split1 tables count
    full-resolution tiles' split level-1 nodes, each ``split1_triangles`` more (with side errors, without: the
    exact rule's four leaves draw 8 each, 16; the lean rule's ``LEAN_SPLIT1_TRIANGLES``, 0). Rows whose nodes have
    side errors (``sides`` (B,) 4, else 1) count their leaves' near sides instead, ``NEAR_SIDE_TRIANGLES`` each.

    The tiles are rows of stacked ``TileNodes``, read in place: ``tables`` the small nodes' ``split_tables`` of every
    kind, coarse (rows, C) errors, boxes (rows, 6, blocks + C) as (hi, lo) corners in world metres, coordinates
    first, root (rows,) and ``sides`` (rows,), of which ``rows`` (B,) are the tiles'. ``inside`` (B,) marks tiles
    wholly inside the frustum, whose boxes need no test. A node splits when E * k_tau exceeds its block's (or,
    large, its own box's) distance: a block's count of each kind is one look-up in its table, errors rounded to
    1/32 octave (``split_tables``)."""
    b = len(rows)
    if not b:
        return np.zeros(0, np.int64), np.zeros(0)
    eye = np.asarray(eye, dtype=np.float64)
    planes = _NO_PLANES if planes is None else np.ascontiguousarray(planes, dtype=np.float64)
    inside = np.zeros(b, np.bool_) if inside is None else np.asarray(inside, np.bool_)
    sides = np.asarray(sides, np.int64)
    if sides.ndim == 0:
        sides = np.full(len(root), int(sides), np.int64)
    from .estimate_loops import estimate_tiles

    weights = np.array([*split1_triangles, 4.0 * NEAR_SIDE_TRIANGLES, NEAR_TRIANGLES], dtype=np.float64)
    rows, root, k = np.asarray(rows, np.int64), np.asarray(root, np.int64), float(k_tau)
    t = tables
    return estimate_tiles(
        t.tables, t.base, rows, coarse, boxes, root, eye, k, planes, inside, lean, beta, sides, weights
    )


_NO_PLANES = np.zeros((0, 4))


class _Rows:
    """Many tiles' TileNodes as stacked arrays, one row per tile, so a frame's tiles are gathered in one
    indexing per field; beyond ``limit`` tiles the least recently used row is reused (never one of the call at
    hand: ``lookup`` stamps its rows with the call's tick)."""

    FIELDS = ("coarse_error", "boxes", "root", "sides")  # as TileNodes has them; the small nodes' errors of
    # KINDS as ``split_tables`` in ``tables``

    def __init__(self, limit: int):
        self.limit = limit
        self.row: dict[TileKey, int] = {}  # key -> row
        self.keys: list[TileKey] = []  # row -> key
        self.arrays: dict = {}  # FIELDS, (rows, ...) each
        self.tables: SplitTables | None = None
        self.stamp = np.zeros(0, np.int64)  # row -> tick of its last use
        self.tick = 0

    def lookup(self, keys) -> np.ndarray:
        """(len(keys),) rows of the keys, -1 where not stored; the stored ones are now the most recently used."""
        self.tick += 1
        get = self.row.get
        rows = np.array([get(k, -1) for k in keys], dtype=np.int64)
        self.stamp[rows[rows >= 0]] = self.tick
        return rows

    def forget(self, keys) -> None:
        """Drop the keys' rows (their tiles changed): built again on their next lookup, their rows reused first."""
        for k in keys:
            r = self.row.pop(k, None)
            if r is not None:
                self.stamp[r] = -1

    def put(self, key, nodes: TileNodes, tables: tuple | None = None) -> int:
        """Store a tile's nodes (and their ``split_tables``, made here if None) as used by the call at hand;
        returns its row."""
        if len(self.row) >= self.limit:
            r = int(self.stamp[: len(self.keys)].argmin())  # the least recently used
            self.row.pop(self.keys[r], None)  # (absent when forgotten)
            self.keys[r] = key
        else:
            r = len(self.keys)
            self.keys.append(key)
            if r >= len(self.stamp):
                self._grow(nodes)
        assert self.tables is not None  # _grow made them with the first row
        self.tables.base[r], self.tables.tables[r] = tables or split_tables([getattr(nodes, kind) for kind in KINDS])
        for f in self.FIELDS:
            self.arrays[f][r] = getattr(nodes, f)
        self.stamp[r] = self.tick
        self.row[key] = r
        return r

    def _grow(self, nodes: TileNodes) -> None:
        """Double the rows (at least 16, at most ``limit``); rows not yet filled count no splits."""
        cap = len(self.stamp)
        new = min(max(2 * cap, 16), self.limit)  # the call's own rows fit: limit >= its tiles
        vals = {f: np.asarray(getattr(nodes, f)) for f in self.FIELDS}
        grown = {
            f: np.zeros((new, *v.shape), v.dtype if f not in ("root", "sides") else np.int64) for f, v in vals.items()
        }
        most = max(getattr(nodes, kind).shape[1] for kind in KINDS)  # a block's nodes of one kind
        tables = SplitTables(
            np.zeros(new, np.int64),
            np.zeros((new, len(KINDS), nodes.fine.shape[0], TABLE_BINS), np.uint16 if most < 1 << 16 else np.uint32),
        )
        if self.arrays:
            assert self.tables is not None  # made with the arrays
            for f in grown:
                grown[f][:cap] = self.arrays[f]
            tables.base[:cap], tables.tables[:cap] = self.tables.base, self.tables.tables
        self.arrays, self.tables = grown, tables
        self.stamp = np.concatenate([self.stamp, np.zeros(new - cap, np.int64)])


class TileletTriangleEstimator:
    """A ``hybrid.contract.TriangleEstimator`` for the tilelet strategy over one tile pyramid.

    Per tile, its ``TileNodes`` are built once; ``build_ms`` adds up the wall time spent building them: one-time
    work per tile, which renderers count apart from planning. With ``background`` (a store's loader thread), a
    new tile of a store with node blocks is left unknown (NaN) rather than built in the caller's thread: its
    build (its block cut first where it needs it) is in ``waiting`` for the loader to run, and a later call
    stores what it built. ``full_res``: the strategies' full-resolution rule
    (hybrid.contract.FULL_RES; "lean": level-0 tiles' leaves counted as every other tile's).
    """

    def __init__(
        self, pyramid: TilePyramid, beta: float = GPU_BETA, lean: bool = True, full_res: str = DEFAULT_FULL_RES
    ):
        self.pyramid = pyramid
        self.beta, self.lean, self.full_res = float(beta), bool(lean), check_full_res(full_res)
        self._rows = _Rows(MAX_TILES)
        self.build_ms, self.builds = 0.0, 0
        self.background = False
        self.waiting: dict = {}  # tiles of the last call left unknown for the loader -> its build (callable)
        self._prepared: dict = {}  # tiles the loader built -> (epoch, TileNodes, split tables)
        self._epoch = 0  # ``forget`` calls so far
        hf = pyramid.hf
        # a tile store whose nodes (as the GPU reads them) come in per-tile blocks: each tile's is one read, no
        # heights, no error pyramid (a periodic extension's near its seams is cut first, as the GPU's upload
        # cuts it); stores without them are not opened here (nodes_for may refuse or load them)
        self._blocks = None
        if (
            isinstance(hf, StoredTerrain)
            and hf.store.attrs.get("node_blocks")
            and int(hf.store.attrs["tile_size"]) == pyramid.n
        ):
            nodes = nodes_for(hf, pyramid.n, beta)
            self._blocks = nodes if nodes.blocks is not None else None

    def _row(self, key: TileKey, deadline: float | None = None) -> int:
        """The new key's row, its nodes built first; -1 (not built) once ``deadline`` (perf_counter s) passed,
        or with ``background`` while the loader has yet to build them (the build then in ``waiting``)."""
        t0 = time.perf_counter()
        got = self._prepared.pop(key, None)
        if got is not None and got[0] == self._epoch:  # built by the loader: stored here, no build in the frame
            return self._stored(key, got[1], got[2], t0)
        ready = self._block_ready(key)
        if ready is not None and self.background:  # the loader cuts the block if need be and builds the nodes
            self.waiting[key] = partial(self._prepare, key, self._epoch)
            return -1
        if deadline is not None and t0 >= deadline:
            return -1
        source = self._blocks if ready is not None else self._global_nodes()
        if source is not None:  # the block the GPU reads (cut here if need be)
            nodes = self._block_nodes(source, key)
        else:
            nodes = tile_nodes(self.pyramid.tile(key), self.beta, self.full_res if key.level == 0 else None)
        return self._stored(key, nodes, None, t0)

    def _block_nodes(self, source, key: TileKey) -> TileNodes:
        """A tile's nodes from its node block in ``source`` (cut first if need be)."""
        data, offsets = tile_node_block(source, key.level, key.tx, key.ty, self.pyramid.n)
        full_res = self.full_res if key.level == 0 else None
        return block_tile_nodes(data, offsets, self.pyramid.n, *self.pyramid.placement(key), full_res, self.beta)

    def _stored(self, key: TileKey, nodes: TileNodes, tables: tuple | None, t0: float) -> int:
        """Store built nodes in their row, counting the build from ``t0`` (perf_counter s); returns the row."""
        r = self._rows.put(key, nodes, tables)
        self.builds += 1
        self.build_ms += (time.perf_counter() - t0) * 1e3
        return r

    def _prepare(self, key: TileKey, epoch: int) -> None:
        """Build a tile's nodes and split tables off the frame (a store's loader thread: thread-safe) for ``_row``
        to store; a build older than the last ``forget`` (``epoch``) is not stored."""
        nodes = self._block_nodes(self._blocks, key)
        self._prepared[key] = (epoch, nodes, split_tables([getattr(nodes, kind) for kind in KINDS]))
        while len(self._prepared) > MAX_TILES:  # builds never asked for again: the oldest out
            self._prepared.pop(next(iter(self._prepared)), None)

    def forget(self, keys) -> None:
        """Build these tiles' nodes again when next asked (their heights or node arrays changed: an edit)."""
        self._epoch += 1  # builds the loader has under way are stale
        self._prepared.clear()
        self._rows.forget(keys)

    def known(self) -> list[TileKey]:
        """The tiles whose nodes are built and kept."""
        return list(self._rows.row)

    def follow_edit(self, change) -> int:
        """Forget the kept tiles an edit changed (``hybrid.contract.TerrainChange``: samples, bounds or the nodes
        their block reads), built again when next asked; returns how many."""
        _, stale = stale_tiles(change, [(k, None) for k in self._rows.row])
        self.forget(stale)
        return len(stale)

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

    def _estimate(
        self, keys, view: View, tau: float, budget_ms: float | None = None, inside=None
    ) -> tuple[np.ndarray, np.ndarray]:
        self._rows.limit = max(self._rows.limit, len(keys))  # a frame's own rows are never reused for it
        deadline = None if budget_ms is None else time.perf_counter() + budget_ms / 1e3
        builds, self.waiting = self.builds, {}
        rows = self._rows.lookup(keys)
        for i in np.flatnonzero(rows < 0).tolist():
            rows[i] = self._row(keys[i], deadline)
        ok = rows >= 0
        if not ok.all():
            missing = [i for i in np.flatnonzero(~ok) if keys[i] not in self.waiting]
            if missing and self.builds == builds:  # at least one build a call: the queue drains
                rows[missing[0]] = self._row(keys[missing[0]])  # (those waiting: the loader's, not here)
                ok = rows >= 0
        a, r = self._rows.arrays, rows[ok]
        if not len(r):
            return np.full(len(rows), np.nan), np.full(len(rows), np.nan)
        assert self._rows.tables is not None  # rows r are stored, so the tables exist
        est = estimate_rows(
            self._rows.tables,
            r,
            a["coarse_error"],
            a["boxes"],
            a["root"],
            view.eye,
            float(view.pixels_per_radian) / tau,
            view.frustum_planes_rel(),
            None if inside is None else inside[ok],
            self.lean,
            self.beta,
            a["sides"],
            (SPLIT1_TRIANGLES, 16) if self.full_res == "exact" else (LEAN_SPLIT1_TRIANGLES, 0),
        )
        if len(r) == len(rows):
            return est[0].astype(np.float64), est[1]
        tri, vis = np.full(len(rows), np.nan), np.full(len(rows), np.nan)
        tri[ok], vis[ok] = est
        return tri, vis

    def many(
        self, selected: Sequence[SelectedTile], view: View, tau: float, budget_ms: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(triangles (B,) float, visible share (B,)) of the selected tiles at ``view`` for the bound tau (pixels).

        With ``budget_ms``, new tiles' nodes are built front to back only until that much wall time is spent (at
        least one a call); the tiles left get NaN for both (unknown this frame, built in a later one)."""
        return self._estimate([s.key for s in selected], view, tau, budget_ms, getattr(selected, "inside", None))

    def __call__(self, key: TileKey, selected: SelectedTile, view: View, tau: float) -> int:
        """Estimated triangles of tile ``key`` at ``view`` for the error bound tau (pixels)."""
        return int(self._estimate([key], view, tau)[0][0])
