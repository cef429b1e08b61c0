"""Edits of a stored terrain: an in-memory copy the editor changes, and every change written through to the store.

A tile store (``hybrid.tiles.store``) holds, besides level 0, what prepare derived from it: the coarser levels, the
tiles' bounds and errors, the raster node arrays (split form with side codes, and the combined form) and each
tile's node block. ``StoreEditing`` keeps the terrain's level 0 in memory (loaded once: stores up to
``MAX_LOAD_SAMPLES``), an in-memory pyramid and node arrays following it (``TilePyramid.follow_edit``,
``raster.edit``: bit-equal to the store's where its errors are measured), and after a window of samples changed
writes through, atomically (``hybrid.tiles.store_edit``): the levels' chunks over the window, the bounds of the
touched tiles, the node arrays' chunks over the rewritten nodes, the blocks of the tiles that read them, the header's
height range (and its source step, dropped once a sample leaves it) and the manifest. A renderer drawing the store
then reads the new files; its pyramid takes the new bounds (``StorePyramid.follow_write``). Nodes beyond those the
tiles read (the padded square's far part) are not rewritten: nothing reads them.
"""

from __future__ import annotations

from typing import cast

from hybrid.errors import TerrabenchError
from hybrid.terrain.edits import Window
from hybrid.terrain.stored import LazyGrid, StoredTerrain
from hybrid.tiles.pyramid import TileKey, TilePyramid
from hybrid.tiles.pyramid_edit import touched_tiles
from hybrid.tiles.quantize import on_step_cells
from hybrid.tiles.sidecodes import holds_side_codes
from hybrid.tiles.store_edit import StoreWrite, WriteReport, level_chunks, level_fill
from raster.edit import edit_state, follow_nodes, reads_changed_nodes
from raster.nodes import global_nodes, tile_node_block


def _check(hf: StoredTerrain) -> None:
    """Refuse, by name, a store an edit cannot be written through to."""
    a = hf.store.attrs
    if a.get("periodic"):
        raise TerrabenchError(f"{hf.path}: a periodic extension is served from its source store; edit the source")
    if not (a.get("nodes") and a.get("node_blocks") and holds_side_codes(hf.store)):
        raise TerrabenchError(
            f"{hf.path}: editing a tile store needs its node arrays with side codes and node "
            f"blocks; run terrabench prepare again on its input with --out {hf.path}"
        )


class StoreEditing:
    """The in-memory copy of a stored terrain an editor changes, and the write-through of each change."""

    def __init__(self, hf: StoredTerrain):
        _check(hf)
        self.hf, self.mem = hf, hf.load()
        self.lazy = cast(LazyGrid, hf.heights)  # the store's level 0 as the terrain reads it
        self.n, self.beta = int(hf.store.attrs["tile_size"]), float(dict(hf.store.attrs["nodes"])["beta"])
        self.pyramid = TilePyramid(self.mem, self.n)
        for side_errors in (True, False):  # before any edit: the state a change is measured against
            global_nodes(self.mem, self.n, self.beta, side_errors)
            edit_state(self.mem, self.n, self.beta, side_errors)
        self.step = hf.source_step
        self.keys: list[TileKey] = []  # the last write's touched tiles
        self.rewritten: list[Window] = []  # and its changed node windows per global level
        self.last = WriteReport()  # and what it wrote

    def write(self, win: Window) -> WriteReport:
        """Bring the in-memory pyramid and node arrays up to date after the samples of ``win`` changed in the copy,
        and write every changed chunk through to the store at once; returns what was written."""
        self.keys = self.pyramid.follow_edit(win)
        self.rewritten = follow_nodes(self.mem, self.n, win, self.beta)
        combined = follow_nodes(self.mem, self.n, win, self.beta, side_errors=False)
        w = StoreWrite(self.hf)
        try:
            self._levels(w, win)
            self._bounds(w, win)
            nodes = global_nodes(self.mem, self.n, self.beta)
            kinds = (("effective", nodes.effective), ("zlo", nodes.zlo), ("zhi", nodes.zhi), ("sides", nodes.sides))
            for name, arrays in kinds:
                _node_chunks(w, name, arrays, self.rewritten)
            _node_chunks(w, "combined", global_nodes(self.mem, self.n, self.beta, False).effective, combined)
            self._blocks(w, nodes)
        except BaseException:
            w.abort()
            raise
        h = self.mem.heights
        lo, hi = float(h.min()), float(h.max())
        if self.step is not None and not self._on_step(win):
            self.step = None
        self.last = w.commit({"height_range": [lo, hi], "source_step": None if self.step is None else list(self.step)})
        self.lazy.range, self.hf.source_step = (lo, hi), self.step
        return self.last

    def _on_step(self, win: Window) -> bool:
        """Whether every sample of the window is on the store's source step (the window grown by one sample, so
        each of its samples is a cell's corner; the samples around were on the step)."""
        h = self.mem.heights
        cells = on_step_cells(h[win.grown(1, *h.shape).slices()], self.step)
        return cells is not None and bool(cells.all())

    def _levels(self, w: StoreWrite, win: Window) -> None:
        """Stage every pyramid level's chunks over the window, from the copy's level 0."""
        h = self.mem.heights
        for level, ids in level_chunks(self.pyramid.max_level + 1, self.n, win, *h.shape).items():
            w.chunks(f"levels/{level}", ids, level_fill(h, level), read=False)

    def _bounds(self, w: StoreWrite, win: Window) -> None:
        """Stage the bounds and errors of every level's touched tiles (one chunk an array)."""
        p = self.pyramid
        for level in range(p.max_level + 1):
            rows, cols = touched_tiles(p, win, level)
            if not len(rows) or not len(cols):
                continue
            at = (slice(rows.start, rows.stop), slice(cols.start, cols.stop))
            for name, arr in zip(("zmin", "zmax", "error"), p.level_arrays(level), strict=True):

                def fill(data, starts, a=arr, at=at):
                    data[at] = a[at]

                w.chunks(f"{name}/{level}", [(0, 0)], fill)

    def _blocks(self, w: StoreWrite, nodes) -> None:
        """Stage the node blocks of every tile whose block reads a rewritten node."""
        for level in range(self.pyramid.max_level + 1):
            ids = [
                (k.ty, k.tx, 0, 0) for k in self.pyramid.keys(level) if reads_changed_nodes(k, self.n, self.rewritten)
            ]
            if ids:

                def fill(data, starts, level=level):
                    for t in range(data.shape[1]):  # a run of tiles along a row
                        data[0, t] = tile_node_block(nodes, level, starts[1] + t, starts[0], self.n)[0]

                w.chunks(f"nodes/blocks/{level}", ids, fill, read=False)


def _node_chunks(w: StoreWrite, name: str, arrays, rewritten: list[Window]) -> None:
    """Stage the chunks of ``nodes/<name>/<g>`` over each level's rewritten node window from the in-memory arrays
    (which hold the nodes tiles read, a prefix of each level: a chunk reaching beyond it keeps the store's there)."""
    for g, win in enumerate(rewritten):
        if win.empty or arrays is None:
            continue
        key, src = f"nodes/{name}/{g}", arrays[g]
        c = w.hf.store[key].chunks[0]
        ids = [
            (a, b) for a in range(win.i0 // c, (win.i1 - 1) // c + 1) for b in range(win.j0 // c, (win.j1 - 1) // c + 1)
        ]

        def fill(data, starts, src=src):
            r1, c1 = min(src.shape[0], starts[0] + data.shape[0]), min(src.shape[1], starts[1] + data.shape[1])
            data[: r1 - starts[0], : c1 - starts[1]] = src[starts[0] : r1, starts[1] : c1]

        def beyond(starts, src=src, c=c, shape=w.hf.store[key].shape):
            return min(starts[0] + c, shape[0]) > src.shape[0] or min(starts[1] + c, shape[1]) > src.shape[1]

        w.chunks(key, ids, fill, read=beyond)
