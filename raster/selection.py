"""GPU-resident tilelet quadtrees: what a tile keeps on the GPU, and the per-frame leaf selection (compute).

At upload a tile gets its heights (a float32 storage buffer), its node errors and boxes with a one-node apron
(raster.nodes), a skirt-segment buffer and a control buffer (its indirect draw commands and leaf list). Per
frame the CPU writes one block of parameters per tile and issues the dispatches: the compute shader
(select.comp.glsl) picks the leaves for the view, drops midpoints toward coarser neighbours, geomorphs and
culls, writes the leaves into the frame's arena (raster.arena, shared by the frame's tiles and sized by what
the view selects) and fills the indirect commands; the draw (geometry shader or indexed triangles, see
raster.tilelets and raster.indexed) reads them.
"""
from __future__ import annotations

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import gl_bytes, gl_finish
from hybrid.gl.programs import compute_shader, set_uniform, write_uniform
from hybrid.gl.textures import terrain_texture

from .arena import LeafArena
from .nodes import nodes_for, pending_cut, tile_levels, tile_node_block
from .quadtree import GPU_BETA
from .tileblock import TileBlocks, register_tile_block, tile_blocks

LEAF_WORDS = 13                 # j0, i0, level, dropped edges, nine post heights
LEAF_FORMAT = "4i 4f 4f 1f"
SEGMENT_WORDS = 6               # skirt segment: x, y, height of both ends
COMMAND_WORDS = 5               # moderngl's indirect command stride: count, instances, first, base, pad
CMD_POINTS, CMD_TEMPLATE, CMD_SKIRTS = 0, 1, 2
FRAME_FIELDS = ("triangles", "tilelets", "tilelets_culled", "skirt_segments", "arena_leaves", "arena_overflow")
BASE_WORD = 15                  # control word: the tile's first leaf in the arena
_LOCAL = 64                     # compute work group size (select.comp.glsl)
FOUND_OFFSET = 256              # bytes: where a tile's control buffer holds the pass-0 leaf list


def _control_blank() -> bytes:
    """A control buffer before selection: the three indirect draws with the counts the selection fills in still
    0, then pass 1's dispatch (x, y, z) and the leaf count."""
    words = np.zeros(FOUND_OFFSET // 4 + 4, np.uint32)
    cmd = words[:3 * COMMAND_WORDS].reshape(3, COMMAND_WORDS)
    cmd[CMD_POINTS, 1] = 1          # leaf points: one instance of (leaf count) points
    cmd[CMD_TEMPLATE, 1] = 1        # mesh: one instance of (24 x leaf count) indices
    cmd[CMD_SKIRTS, 0] = 6          # skirts: (segment count) instances of a 6-vertex quad
    words[FOUND_OFFSET // 4:] = (0, 1, 1, 0)
    return words.tobytes()


CONTROL_BLANK = _control_blank()


def level_starts(n: int) -> np.ndarray:
    """Invocation index of the first node of each local level in the listing pass (levels + 1 entries): level 0
    is listed by its split parents (levels 0 and 1 both start at 0), except in a 2-cell tile."""
    levels = tile_levels(n)
    counts = [0 if levels > 1 else 1] + [(n >> (m + 1)) ** 2 for m in range(1, levels)]
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)


def level_bounds(data: np.ndarray, offsets: np.ndarray, n: int, spacing_xy: tuple[float, float]):
    """Per local level of a tile: largest effective error (m) and the union of its own nodes' boxes (tile-local m);
    ``spacing_xy`` is the tile's (x, y) sample spacing in metres."""
    levels = len(offsets) - 1
    sp = np.asarray(spacing_xy, dtype=np.float64)
    err, lo, hi = np.zeros(levels), np.zeros((levels, 3)), np.zeros((levels, 3))
    for m in range(levels):
        side = n >> (m + 1)
        own = data[offsets[m]:offsets[m + 1]].reshape(side + 2, side + 2, 4)[1:-1, 1:-1]
        grow = (2 << m) * sp
        err[m] = own[..., 0].max()
        lo[m] = (*(-grow), own[..., 1].min())
        hi[m] = (*(n * sp + grow), own[..., 2].max())
    return err, lo, hi


def first_levels(gs, eye_local: np.ndarray, k_tau: float) -> np.ndarray:
    """Per tile (all of one cell count), the finest local level that can hold a leaf in this view (below it no
    parent can split); ``eye_local`` (B, 3) is the eye minus each tile's origin, metres."""
    lo = np.stack([g.level_lo for g in gs])
    hi = np.stack([g.level_hi for g in gs])
    err = np.stack([g.level_error for g in gs])
    d = np.linalg.norm(np.maximum(np.maximum(lo - eye_local[:, None], eye_local[:, None] - hi), 0.0), axis=2)
    can = err * k_tau > d                                 # (B, levels): a parent at this level can split
    top = can.shape[1] - 1
    if top <= 0:
        return np.zeros(len(gs), dtype=np.int64)
    inner = can[:, 1:top]                                 # level m + 1 for m = 0 .. top - 2
    hit = inner.any(axis=1)
    return np.where(hit, np.argmax(inner, axis=1) if inner.shape[1] else 0, top - 1)


def slot_buffers(ctx, n: int):
    """(skirt segments, control) buffers of one drawing of an n-cell tile: room for every segment and leaf."""
    return (ctx.buffer(reserve=max(4 * n, 8) * SEGMENT_WORDS * 4),
            ctx.buffer(reserve=FOUND_OFFSET + (4 + (n // 2) ** 2) * 4))


class DrawSlot:
    """Control and skirt buffers for a second drawing of a tile in one frame (a tile drawn for several missing
    finer ones, each clipped to its own rectangle, selects its leaves once for each)."""

    def __init__(self, strategy, n: int):
        self.n = n
        self.segments, self.control = slot_buffers(strategy.ctx, n)
        self.vaos = strategy.tile_arrays(self)

    @property
    def nbytes(self) -> int:
        """GPU bytes of the slot's buffers, as the driver reports them."""
        return gl_bytes(self.segments, self.control)

    def release(self) -> None:
        """Free the buffers."""
        for v in self.vaos.values():
            v.release()
        self.segments.release()
        self.control.release()


class SelectedTileletTile:
    """GPU objects of one tile: heights, node data, skirt buffer, and a control buffer with the indirect draw
    commands and the tile's arena base at its start and the pass-0 leaf list at FOUND_OFFSET (the leaves
    themselves are in the strategy's arena)."""

    def __init__(self, strategy, tile):
        ctx = strategy.ctx
        h = np.ascontiguousarray(tile.heights, dtype=np.float32)
        if h.ndim != 2 or h.shape[0] != h.shape[1] or (h.shape[0] - 1) & (h.shape[0] - 2) or h.shape[0] < 3:
            raise TerrabenchError(f"tile heights must be (n+1)² with n a power of two >= 2, got shape {h.shape}")
        self.n = h.shape[0] - 1
        self.key = tile.key
        nodes = nodes_for(strategy.hf, self.n, strategy.beta)
        data, self.offsets = tile_node_block(nodes, int(tile.key.level), int(tile.key.tx), int(tile.key.ty), self.n)
        self.side_errors = nodes.sides is not None          # the terrain's nodes carry side codes
        self.starts = level_starts(self.n)
        self.level_error, self.level_lo, self.level_hi = level_bounds(data, self.offsets, self.n, tile.spacing_xy)
        self.heights = ctx.buffer(h.tobytes())
        self.nodes = ctx.buffer(data.tobytes())
        self.segments, self.control = slot_buffers(ctx, self.n)
        self.writes = strategy.writes
        self.vaos = strategy.tile_arrays(self)

    @property
    def nbytes(self) -> int:
        """GPU bytes of the tile's textures and buffers, as the driver reports them."""
        return gl_bytes(self.heights, self.nodes, self.segments, self.control)

    def release(self) -> None:
        """Free the GPU objects."""
        for v in self.vaos.values():
            v.release()
        for o in (self.segments, self.control, self.nodes, self.heights):
            o.release()


class TileletSelection:
    """The part the two tilelet strategies share: terrain texture, the selection shader, the leaf arena,
    per-tile GPU data."""

    kind = "raster"
    writes = "records"          # what the selection writes for the draw: leaf records or a mesh

    def __init__(self, ctx, hf, beta: float = GPU_BETA):
        if not (0.0 < beta < 1.0):
            raise TerrabenchError(f"beta must lie in (0, 1), got {beta!r}")
        self.ctx, self.hf, self.beta = ctx, hf, float(beta)
        register_tile_block(ctx)
        self.passes = tuple(compute_shader(ctx, "raster", "select.comp.glsl", {"PASS": k}) for k in (0, 1))
        self.texture = terrain_texture(ctx, hf)
        self.frame = ctx.buffer(reserve=4 * len(FRAME_FIELDS))
        self.blocks = TileBlocks(ctx)
        self.arena = LeafArena(ctx, self.writes)
        self.spare_slots: dict[int, list[DrawSlot]] = {}     # cell count -> slots for repeated tiles
        self.slots: list = []                                # the last selection's slot of every item

    @property
    def shared_nbytes(self) -> int:
        """GPU bytes shared by all tiles, as the driver reports them: colour texture, frame counters, tile
        blocks, leaf arena."""
        return (gl_bytes(self.texture, self.frame, self.blocks.buffer) + self.arena.nbytes +
                sum(s.nbytes for slots in self.spare_slots.values() for s in slots))

    def upload(self, tile) -> SelectedTileletTile:
        """Put one tile on the GPU: heights, node errors and boxes, skirt and control buffers."""
        return SelectedTileletTile(self, tile)

    def host_work(self, key, n: int):
        """Slow CPU work of tile ``key``'s upload (n cells a side) that a loader thread can do ahead, as a callable
        (a periodic extension's node block cut near a seam), or None."""
        return pending_cut(self.hf, n, self.beta, key)

    def tile_arrays(self, g: SelectedTileletTile) -> dict:
        """The vertex arrays a strategy draws a tile's leaves with (subclasses)."""
        raise NotImplementedError

    def set_selection(self, name: str, value) -> None:
        """Set a uniform of both selection passes (where the pass uses it)."""
        for prog in self.passes:
            set_uniform(prog, name, value)

    def frame_blocks(self, view, items, tau: float, culling: bool = True, skirts: dict | None = None):
        """The frame's per-tile shader blocks (raster.tileblock) with the selection's fields, uploaded."""
        k_tau = float(view.pixels_per_radian) / float(tau)

        def selection_fields(blocks):
            gs = [g for g, _, _ in items]
            for n in {g.n for g in gs}:                   # one cell count per frame in practice
                at = np.array([g.n == n for g in gs])
                sub = [g for g in gs if g.n == n]
                eye_local = np.asarray(view.eye, dtype=np.float64) - np.array([t.origin for _, t, _ in items])[at]
                first = sub[0].starts[first_levels(sub, eye_local, k_tau)]
                b = blocks[at]
                b["shape"][:, 0], b["shape"][:, 1], b["shape"][:, 2] = n, tile_levels(n) - 1, first
                b["offsets"][:, :len(sub[0].offsets)] = sub[0].offsets
                b["starts"][:, :len(sub[0].starts)] = sub[0].starts
                blocks[at] = b

        blocks = tile_blocks(self.hf, view, items, skirts, culling, per_frame=selection_fields)
        self.blocks.write(blocks)
        return blocks

    def select_leaves(self, view, items, tau: float, culling: bool = True, skirts: dict | None = None) -> None:
        """Run the leaf selection of every item for the view at tau pixels; fills each tile's commands.

        Per tile: pass 0 over its nodes lists the leaves, pass 1 (dispatched from their count) emits them; all
        tiles' pass 0 run before any pass 1. The frame's tile blocks stay uploaded for the draw.
        """
        if not (np.isfinite(tau) and tau > 0):
            raise TerrabenchError(f"tau must be finite and > 0 pixels, got {tau!r}")
        blocks = self.frame_blocks(view, items, tau, culling, skirts)
        planes = view.frustum_planes_rel().astype(np.float32).tobytes()
        for prog in self.passes:
            write_uniform(prog, "planes", planes)
        self.set_selection("k_tau", float(view.pixels_per_radian) / float(tau))
        self.set_selection("beta", self.beta)
        self.set_selection("write_records", self.writes == "records")
        self.set_selection("write_mesh", self.writes == "mesh")
        self.set_selection("arena_capacity", int(self.arena.capacity))
        self.set_selection("eye_terrain", tuple(float(e - o) for e, o in zip(view.eye, self.hf.origin)))
        self.set_selection("cell_metres", (float(self.hf.spacing_x), float(self.hf.spacing_y)))
        self.set_selection("side_errors", bool(items) and items[0][0].side_errors)
        self.frame.write(np.zeros(len(FRAME_FIELDS), np.uint32).tobytes())
        self.frame.bind_to_storage_buffer(4)
        self.arena.bind()
        list_pass, emit_pass = self.passes
        self.slots = self.draw_slots([g for g, _, _ in items])
        # every tile's listing, one barrier, every tile's emission: a tile's passes touch only its own buffers,
        # its arena range and the frame's counters (atomics), so the tiles' dispatches need no barrier between
        # them and a GPU may run them together
        for i, ((g, _, _), slot) in enumerate(zip(items, self.slots)):
            slot.control.write(CONTROL_BLANK)
            self._bind_item(i, g, slot)
            first = int(blocks[i]["shape"][2])
            list_pass.run(group_x=(int(g.starts[-1]) - first + _LOCAL - 1) // _LOCAL)
        self.ctx.memory_barrier()
        for i, ((g, _, _), slot) in enumerate(zip(items, self.slots)):
            self._bind_item(i, g, slot)
            slot.segments.bind_to_storage_buffer(3)
            g.heights.bind_to_storage_buffer(5)
            emit_pass.run_indirect(slot.control, offset=FOUND_OFFSET)
        self.ctx.memory_barrier()

    def _bind_item(self, i: int, g, slot) -> None:
        """Bind what both selection passes read of item i: its tile block, its tile's nodes, its slot's commands and
        leaf list."""
        self.blocks.bind(i)
        g.nodes.bind_to_storage_buffer(0)
        slot.control.bind_to_storage_buffer(2, size=FOUND_OFFSET)
        slot.control.bind_to_storage_buffer(6, offset=FOUND_OFFSET)

    def draw_slots(self, gs: list) -> list:
        """Where each item's selection goes: its tile's own buffers the first time the tile is in the list,
        a spare slot (made once, kept for later frames) each further time."""
        seen, used, out = set(), {}, []
        for g in gs:
            if id(g) not in seen:
                seen.add(id(g))
                out.append(g)
                continue
            k = used.get(g.n, 0)
            used[g.n] = k + 1
            pool = self.spare_slots.setdefault(g.n, [])
            if k == len(pool):
                pool.append(DrawSlot(self, g.n))
            out.append(pool[k])
        return out

    def frame_counters(self) -> dict:
        """Counters of the last selection, summed over its tiles (one read of a small buffer, after a wait that
        lets other threads run)."""
        gl_finish(self.ctx)
        raw = np.frombuffer(self.frame.read(), dtype=np.uint32)
        return {f: int(v) for f, v in zip(FRAME_FIELDS, raw)}

    def release(self) -> None:
        """Free the selection shader, the texture, the counters, the arena and the spare slots."""
        for slots in self.spare_slots.values():
            for s in slots:
                s.release()
        self.arena.release()
        self.blocks.release()
        for o in (*self.passes, self.texture, self.frame):
            if o is not None:
                o.release()
