"""GPU-resident tilelet quadtrees: what a tile keeps on the GPU, and the per-frame leaf selection (compute).

At upload a tile's heights and its node errors and boxes with a one-node apron (raster.nodes) go into a slot of
its cell count's heap (raster.heap). Per frame the CPU writes one block of parameters per item (a drawing of a
tile: raster.tileblock, with where its tile's slot and its own outputs lie), the items' blank draw commands and
pass 0's work table (raster.frame_items), and issues two dispatches over all items: the compute shader
(select.comp.glsl) picks the leaves for the view, drops midpoints toward coarser neighbours, geomorphs and
culls, writes the leaves into the frame's arena (raster.arena, shared by the frame's tiles and sized by what
the view selects) and fills each item's indirect commands; the draw (geometry shader or indexed triangles, see
raster.tilelets and raster.indexed) reads them.
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import gl_bytes, gl_finish, gl_memory_barrier
from hybrid.gl.programs import UniformCache, compute_shader, write_uniform
from hybrid.gl.textures import terrain_texture

from .arena import LeafArena, arena_defines
from .frame_items import COMMANDS_PER_ITEM, CONTROL_WORDS, ITEM_DEFINES, LOCAL, FrameItems
from .heap import HEAP_DEFINES, TileHeap, slot_bytes
from .host_nodes import HostNodes, bounds_rows, host_nodes, level_starts
from .morph import TURN_FROM
from .nodes import nodes_for, pending_cut, tile_levels
from .quadtree import GPU_BETA, check_full_res
from .tileblock import (
    BLOCK,
    BLOCK_DEFINES,
    CONSTANT_WORDS,
    MAX_STARTS,
    STARTS_FOUND,
    STARTS_HEIGHTS,
    STARTS_SEGMENTS,
    TILE_BLOCKS_BINDING,
    TileBlocks,
    register_tile_block,
    static_blocks,
    tile_constants,
    view_fields,
)

LEAF_FORMAT = "4i 4f 4f 1f"  # a leaf record: j0, i0, level, dropped edges, nine post heights
LEAN_LEAF_FORMAT = "4i 4f 4f 1f 2f"  # full_res "lean": and the SE and NW cells' turns (15 words)
FRAME_FIELDS = ("triangles", "tilelets", "tilelets_culled", "skirt_segments", "arena_leaves", "arena_overflow")
FRAME_BINDING = 4  # storage binding of the frame's counters (FRAME_FIELDS)
MAX_RESERVED_BYTES = 512 << 20  # the most GPU memory a heap holds from the start, whatever the budget


def full_res_defines(full_res: str) -> dict:
    """The shader defines of a full-resolution rule (select.comp.glsl, leaf.vert.glsl, tilelet.geom.glsl)."""
    return {"LEAN_FULL_RES": 1, "TURN_FROM": f"{TURN_FROM!r}"} if full_res == "lean" else {}


def select_defines(full_res: str, k: int) -> dict:
    """Every define of selection pass ``k`` (select.comp.glsl): buffer layouts and bindings, the full-resolution
    rule's and the pass's."""
    return {
        "PASS": k,
        "TILE_BLOCKS_STORAGE": 1,
        **BLOCK_DEFINES,
        "FRAME_BINDING": FRAME_BINDING,
        "ARENA_FIELD": FRAME_FIELDS.index("arena_leaves"),
        "OVERFLOW_FIELD": FRAME_FIELDS.index("arena_overflow"),
        **ITEM_DEFINES,
        **HEAP_DEFINES,
        **arena_defines(full_res),
        **full_res_defines(full_res),
    }


def first_levels(bounds: np.ndarray, eye_local: np.ndarray, k_tau: float) -> np.ndarray:
    """Per tile (all of one cell count), the finest local level that can hold a leaf in this view (below it no
    parent can split); ``bounds`` (B, levels, 7) are the tiles' ``host_nodes.bounds_rows`` rows (lo, hi, error), ``eye_local``
    (B, 3) is the eye minus each tile's origin, metres."""
    lo, hi, err = bounds[..., 0:3], bounds[..., 3:6], bounds[..., 6]
    gap = np.maximum(np.maximum(lo - eye_local[:, None], eye_local[:, None] - hi), 0.0)
    can = err * k_tau > np.sqrt(np.einsum("bmk,bmk->bm", gap, gap))  # (B, levels): a parent here can split
    top = can.shape[1] - 1
    if top <= 0:
        return np.zeros(len(bounds), dtype=np.int64)
    inner = can[:, 1:top]  # level m + 1 for m = 0 .. top - 2
    hit = inner.any(axis=1)
    return np.where(hit, np.argmax(inner, axis=1) if inner.shape[1] else 0, top - 1)


class SelectedTileletTile:
    """One resident tile of a tilelet strategy: its slot in its cell count's heap (heights and node data) and
    what the frame's selection needs to know of it."""

    def __init__(self, strategy, tile):
        h = np.ascontiguousarray(tile.heights, dtype=np.float32)
        if h.ndim != 2 or h.shape[0] != h.shape[1] or (h.shape[0] - 1) & (h.shape[0] - 2) or h.shape[0] < 3:
            raise TerrabenchError(f"tile heights must be (n+1)² with n a power of two >= 2, got shape {h.shape}")
        self.n = h.shape[0] - 1
        self.key = tile.key
        host = getattr(tile, "host", {}).pop(strategy.host_product, None)  # made by a store's loader thread
        if not isinstance(host, HostNodes) or host.key != tile.key or host.beta != strategy.beta:
            host = host_nodes(strategy.hf, self.n, strategy.beta, tile.key)
        data, self.offsets = host.data, host.offsets
        self.side_errors = nodes_for(strategy.hf, self.n, strategy.beta).sides is not None  # side codes held
        self.starts = level_starts(self.n)
        if len(self.starts) > MAX_STARTS:
            raise TerrabenchError(
                f"tiles of {self.n} cells have {len(self.starts) - 1} local levels; the raster "
                f"selection handles at most {MAX_STARTS - 1}"
            )
        err, lo, hi = bounds_rows(host.err, host.zlo, host.zhi, self.n, tile.spacing_xy)
        constants, self.clip = tile_constants(tile), tile.clip  # the tile block's own part ...
        block = static_blocks(strategy.hf, constants[None])  # ... and what the view leaves
        block["shape"][:, 0], block["shape"][:, 1] = self.n, tile_levels(self.n) - 1  # as it is (node offsets
        block["offsets"][:, : len(self.offsets)] = self.offsets  # within the slot's)
        block["starts"][:, : len(self.starts)] = self.starts
        # both joined as bytes per frame (concatenating structured arrays is slow): the block, and the constants
        # followed by the level bounds (levels, 7: lo, hi, error, tile-local metres) that first_levels reads
        self.block = block.tobytes()
        self.numbers = np.concatenate([constants, np.concatenate([lo, hi, err[:, None]], axis=1).ravel()]).tobytes()
        self.slot = strategy.heap(self.n, len(data)).alloc(h, data)
        self.writes = strategy.writes

    @property
    def nbytes(self) -> int:
        """GPU bytes of the tile's heap slot (its heights and nodes)."""
        return self.slot.nbytes

    def release(self) -> None:
        """Give the heap slot back."""
        self.slot.release()


class TileletSelection:
    """The part the two tilelet strategies share: terrain texture, the selection shader, the heaps of resident
    tiles, the frame's item buffers and leaf arena."""

    kind = "raster"
    writes = "records"  # what the selection writes for the draw: leaf records or a mesh

    def __init__(self, ctx, hf, beta: float = GPU_BETA):
        if not (0.0 < beta < 1.0):
            raise TerrabenchError(f"beta must lie in (0, 1), got {beta!r}")
        self.ctx, self.hf, self.beta = ctx, hf, float(beta)
        register_tile_block(ctx)
        self.full_res = "exact"
        self._passes = {"exact": self._compile_passes("exact")}
        self.passes = self._passes["exact"]
        self.texture = terrain_texture(ctx, hf)
        self.frame = ctx.buffer(reserve=4 * len(FRAME_FIELDS))
        self.blocks = TileBlocks(ctx)
        self.arena = LeafArena(ctx, self.writes)
        self.items = FrameItems(ctx)
        self.heaps: dict[int, TileHeap] = {}  # cell count -> heap of resident tiles
        self._reserved: dict[int, tuple[int, int]] = {}  # cell count -> (bytes, tiles) its heap holds at first
        self._counts_spare = True  # whether shared_nbytes counts the heaps' spare bytes (not where another does)
        self.item_of: dict[int, int] = {}  # id(tile) -> its first item in the last selection
        self.uniforms = UniformCache()  # the selection passes' and the draw programs'

    def _compile_passes(self, full_res: str) -> tuple:
        """The selection's two passes for a full-resolution rule."""
        return tuple(
            compute_shader(self.ctx, "raster", "select.comp.glsl", select_defines(full_res, k)) for k in (0, 1)
        )

    def use_full_res(self, full_res: str) -> None:
        """Select and lay out leaves by the full-resolution rule ``full_res`` (hybrid.contract.FULL_RES) from now on."""
        if check_full_res(full_res) == self.full_res:
            return
        if full_res not in self._passes:
            self._passes[full_res] = self._compile_passes(full_res)
        self.passes, self.full_res = self._passes[full_res], full_res
        self.arena.use_layout(full_res)

    def heap(self, n: int, node_rows: int) -> TileHeap:
        """The heap of n-cell tiles (made at the first, with the slots ``reserve`` asked for)."""
        if n not in self.heaps:
            nbytes, tiles = self._reserved.get(n, (0, 0))
            want = min(min(nbytes, MAX_RESERVED_BYTES) // slot_bytes(n, node_rows), tiles)
            # one slot beyond: an upload takes its slot before the residency cache evicts to make room for it
            self.heaps[n] = TileHeap(self.ctx, n, node_rows, min_slots=want + 1 if want else 0)
        return self.heaps[n]

    def reserve(self, n: int, nbytes: int, tiles: int) -> None:
        """Hold about ``nbytes`` of GPU memory (at most ``MAX_RESERVED_BYTES``), or room for ``tiles`` n-cell tiles if
        less, from the heap's making on (a renderer's budget of resident tiles, and its pyramid's tiles), so that
        the heap does not grow inside a frame."""
        self._reserved[int(n)] = (max(int(nbytes), 0), max(int(tiles), 0))

    @property
    def heap_key(self) -> tuple[int, float]:
        """What a heap slot's layout depends on (the terrain, beta): strategies of equal keys may share heaps."""
        return (id(self.hf), self.beta)

    def share_heaps(self, owner: TileletSelection) -> None:
        """Keep this strategy's resident tiles in ``owner``'s heaps from now on (before any upload): the raster
        strategies of one renderer then fill one pool, which either may fill alone, where pools of their own
        would each hold part of the budget and grow whenever the choices lean one way. ``owner`` counts the
        heaps' spare bytes; its ``reserve`` sizes them."""
        if self.heaps:
            raise TerrabenchError("a strategy shares heaps before its first upload, not after")
        if owner.heap_key != self.heap_key:
            raise TerrabenchError("strategies share heaps only over one terrain and one beta (their slots' layout)")
        self.heaps, self._reserved, self._counts_spare = owner.heaps, owner._reserved, False

    @property
    def spare_nbytes(self) -> int:
        """GPU bytes of the heaps that no tile holds, as the driver reports them; 0 where the heaps are another
        strategy's (``share_heaps``), which counts them."""
        return sum(h.spare_nbytes for h in self.heaps.values()) if self._counts_spare else 0

    @property
    def shared_nbytes(self) -> int:
        """GPU bytes shared by all tiles, as the driver reports them: colour texture, frame counters, tile
        blocks, item buffers, leaf arena, and the heaps' bytes no tile holds (``spare_nbytes``)."""
        g = gl_bytes(self.texture, self.frame, self.blocks.buffer)
        return g + self.arena.nbytes + self.items.nbytes + self.spare_nbytes

    def upload(self, tile) -> SelectedTileletTile:
        """Put one tile on the GPU: heights, node errors and boxes, in its heap."""
        return SelectedTileletTile(self, tile)

    host_product = "raster.nodes"  # the name of what host_prepare makes of a tile (StorePyramid.derive)

    def host_prepare(self, heights: np.ndarray, source_step=None, key=None) -> HostNodes:
        """The CPU part of tile ``key``'s upload, which a store's loader thread runs ahead: its node block and the
        block's per-level extremes (``raster.host_nodes``); ``heights`` give its cell count."""
        return host_nodes(self.hf, int(heights.shape[0]) - 1, self.beta, key)

    def host_work(self, key, n: int):
        """Slow CPU work of tile ``key``'s upload (n cells a side) that a loader thread can do ahead, as a callable
        (a periodic extension's node block cut near a seam), or None."""
        return pending_cut(self.hf, n, self.beta, key)

    def set_selection(self, name: str, value) -> None:
        """Set a uniform of both selection passes (where the pass uses it; not sent again while unchanged)."""
        for prog in self.passes:
            self.uniforms.set(prog, name, value)

    def frame_blocks(self, view, items, tau: float, culling: bool, skirts: dict | None, lod_eye: np.ndarray):
        """The frame's per-item shader blocks (raster.tileblock) with the selection's fields, uploaded; and each
        item's pass-0 work groups (from ``lod_eye``, world metres). What a tile's block holds whatever the view was
        made at its upload."""
        gs = [g for g, _, _ in items]
        g0 = gs[0]  # every item has g0's cell count (select_leaves)
        numbers = np.frombuffer(bytearray(b"".join([g.numbers for g in gs])), np.float64).reshape(len(gs), -1)
        constants = numbers[:, :CONSTANT_WORDS]
        for i, (g, t, _) in enumerate(items):
            if g.clip != t.clip:  # a tile drawn for a missing one (hybrid.uploads) has that one's clip
                constants[i] = tile_constants(t)
        blocks = view_fields(
            np.frombuffer(bytearray(b"".join([g.block for g in gs])), BLOCK),
            view,
            constants,
            [s for _, _, s in items],
            skirts,
            culling,
        )
        eye_local = lod_eye - constants[:, 0:3]
        bounds = numbers[:, CONSTANT_WORDS:].reshape(len(gs), -1, 7)
        first = g0.starts[first_levels(bounds, eye_local, float(view.pixels_per_radian) / float(tau))]
        groups0 = (int(g0.starts[-1]) - first + LOCAL - 1) // LOCAL
        blocks["shape"][:, 2] = first
        nodes_base, heights_base = g0.slot.heap.bases([g.slot for g in gs])  # slots move when heaps do
        blocks["offsets"][:, : len(g0.offsets)] += nodes_base[:, None]
        blocks["starts"][:, STARTS_HEIGHTS] = heights_base
        found_base, seg_base, table1_start = self.items.prepare(g0.n, groups0, self.arena.capacity)
        blocks["starts"][:, STARTS_FOUND], blocks["starts"][:, STARTS_SEGMENTS] = found_base, seg_base
        self.blocks.write(blocks)
        return blocks, groups0, table1_start

    def select_leaves(
        self, view, items, tau: float, culling: bool = True, skirts: dict | None = None, lod_eye=None
    ) -> None:
        """Run the leaf selection of every item for the view at tau pixels; fills each item's commands.
        ``lod_eye`` (world metres; default the view's eye) is where the leaves' distances, and so their levels
        and morph factors, are measured from: another eye holds a level of detail while the view moves.

        Pass 0 over every item's nodes lists the leaves and, as each item's are counted, places them in the arena
        and writes pass 1's work table; pass 1 (dispatched from that table's length) emits them: one dispatch a
        pass, so the items must share one cell count (a pyramid's tiles do). The frame's tile blocks stay uploaded
        for the draw.
        """
        if not (np.isfinite(tau) and tau > 0):
            raise TerrabenchError(f"tau must be finite and > 0 pixels, got {tau!r}")
        self.item_of = {}
        for i, (g, _, _) in enumerate(items):
            self.item_of.setdefault(id(g), i)
        if not items:
            return
        ns = sorted({g.n for g, _, _ in items})
        if len(ns) > 1:
            raise TerrabenchError(f"a frame's raster tiles must have one cell count, got {ns}")
        if lod_eye is None:
            lod_eye = np.asarray(view.eye, dtype=np.float64)
        else:  # a view's eye is checked where the view is made
            lod_eye = np.asarray(lod_eye, dtype=np.float64)
            if lod_eye.shape != (3,) or not np.isfinite(lod_eye).all():
                raise TerrabenchError(f"lod_eye must be three finite metres (x, y, z), got {lod_eye.tolist()}")
        _blocks, groups0, table1_start = self.frame_blocks(view, items, tau, culling, skirts, lod_eye)
        planes = view.frustum_planes_rel().astype(np.float32).tobytes()
        for prog in self.passes:
            write_uniform(prog, "planes", planes)
        self.set_selection("k_tau", float(view.pixels_per_radian) / float(tau))
        self.set_selection("beta", self.beta)
        self.set_selection("write_records", self.writes == "records")
        self.set_selection("write_mesh", self.writes == "mesh")
        self.set_selection("arena_capacity", int(self.arena.capacity))
        self.set_selection("eye_terrain", tuple((lod_eye - self.hf.origin).tolist()))
        self.set_selection("cell_metres", (float(self.hf.spacing_x), float(self.hf.spacing_y)))
        self.set_selection("side_errors", items[0][0].side_errors)
        self.set_selection("table1_start", int(table1_start))
        self.frame.write(np.zeros(len(FRAME_FIELDS), np.uint32).tobytes())
        self.frame.bind_to_storage_buffer(FRAME_BINDING)
        self.blocks.buffer.bind_to_storage_buffer(TILE_BLOCKS_BINDING)
        self.arena.bind()
        self.items.bind()
        list_pass, emit_pass = self.passes
        self.heaps[ns[0]].bind()
        list_pass.run(group_x=int(groups0.sum()))
        gl_memory_barrier(self.ctx)
        emit_pass.run_indirect(self.items.work)
        gl_memory_barrier(self.ctx)

    def command(self, item: int, which: int) -> int:
        """Index of item ``item``'s indirect command ``which`` (CMD_*) in the control buffer."""
        return COMMANDS_PER_ITEM * item + which

    def control_words(self, item: int) -> np.ndarray:
        """Item ``item``'s control words of the last selection (CONTROL_WORDS,), read back (for tests)."""
        return np.frombuffer(
            self.items.control.read(size=CONTROL_WORDS * 4, offset=CONTROL_WORDS * 4 * item), dtype=np.uint32
        )

    def frame_counters(self) -> dict:
        """Counters of the last selection, summed over its tiles (one read of a small buffer, after a wait that
        lets other threads run)."""
        gl_finish(self.ctx)
        raw = np.frombuffer(self.frame.read(), dtype=np.uint32)
        return {f: int(v) for f, v in zip(FRAME_FIELDS, raw)}

    def release(self) -> None:
        """Free the selection shader, the texture, the counters, the arena, the item buffers and the heaps."""
        for h in self.heaps.values():
            h.release()
        self.heaps = {}
        self.arena.release()
        self.items.release()
        self.blocks.release()
        for o in (*(q for ps in self._passes.values() for q in ps), self.texture, self.frame):
            if o is not None:
                o.release()
