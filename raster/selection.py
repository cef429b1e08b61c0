"""GPU-resident tilelet quadtrees: what a tile keeps on the GPU, and the per-frame leaf selection (compute).

At upload a tile gets its heights (a float32 storage buffer), its node errors and boxes with a one-node apron
(raster.nodes), a leaf buffer with room for every possible leaf, a skirt-segment buffer and its indirect draw
commands. Per frame the CPU only sets uniforms: the compute shader (select.comp.glsl) picks the leaves for the
view, drops midpoints toward coarser neighbours, geomorphs and culls, and fills the indirect commands; the
draw (geometry shader or instanced template, see raster.tilelets and raster.instanced) reads them.
"""
from __future__ import annotations

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import gl_bytes
from hybrid.gl.programs import compute_shader, set_uniform
from hybrid.gl.textures import terrain_texture

from .nodes import global_nodes, tile_levels, tile_node_block
from .quadtree import DEFAULT_BETA

LEAF_WORDS = 13                 # j0, i0, level, dropped edges, nine post heights
LEAF_FORMAT = "4i 4f 4f 1f"
SEGMENT_WORDS = 6               # skirt segment: x, y, height of both ends
COMMAND_WORDS = 5               # moderngl's indirect command stride: count, instances, first, base, pad
CMD_POINTS, CMD_TEMPLATE, CMD_SKIRTS = 0, 1, 2
FRAME_FIELDS = ("triangles", "tilelets", "tilelets_culled", "skirt_segments")
_LOCAL = 64                     # compute work group size (select.comp.glsl)
FOUND_BLANK = np.array([0, 1, 1, 0], np.uint32).tobytes()    # pass-1 dispatch (x, y, z) and leaf count
COMMANDS_BLANK = np.array([0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 6, 0, 0, 0, 0], np.uint32).tobytes()
"""Indirect draws before selection: leaf points, template vertices (24 a leaf), skirt quads (instances)"""


def level_starts(n: int) -> np.ndarray:
    """Invocation index of the first node of each local level among a tile's own nodes (levels + 1 entries)."""
    counts = [(n >> (m + 1)) ** 2 for m in range(tile_levels(n))]
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)


def level_bounds(data: np.ndarray, offsets: np.ndarray, n: int, spacing: float):
    """Per local level of a tile: largest effective error (m) and the union of its own nodes' boxes (tile-local m)."""
    levels = len(offsets) - 1
    err, lo, hi = np.zeros(levels), np.zeros((levels, 3)), np.zeros((levels, 3))
    for m in range(levels):
        side = n >> (m + 1)
        own = data[offsets[m]:offsets[m + 1]].reshape(side + 2, side + 2, 4)[1:-1, 1:-1]
        grow = (2 << m) * spacing
        err[m] = own[..., 0].max()
        lo[m] = (-grow, -grow, own[..., 1].min())
        hi[m] = (n * spacing + grow, n * spacing + grow, own[..., 2].max())
    return err, lo, hi


def first_level(g, eye_local: np.ndarray, k_tau: float) -> int:
    """The finest local level that can hold a leaf in this view: below it no parent can split."""
    d = np.linalg.norm(np.maximum(np.maximum(g.level_lo - eye_local, eye_local - g.level_hi), 0.0), axis=1)
    can = g.level_error * k_tau > d
    top = len(can) - 1
    for m in range(top):
        if m + 1 >= top or can[m + 1]:
            return m
    return 0


def skirt_bottom(tile, view) -> float:
    """Eye-relative z (metres) of the lower edge of a tile's skirts: below its lowest point."""
    return float(tile.zmin - view.eye[2] - 1.0 - 0.01 * tile.spacing)


def _padded(values: np.ndarray, size: int) -> tuple:
    out = np.zeros(size, np.int32)
    out[:len(values)] = values
    return tuple(int(v) for v in out)


class SelectedTileletTile:
    """GPU objects of one tile: heights, node data, leaf and skirt buffers, indirect commands."""

    def __init__(self, strategy, tile):
        ctx = strategy.ctx
        h = np.ascontiguousarray(tile.heights, dtype=np.float32)
        if h.ndim != 2 or h.shape[0] != h.shape[1] or (h.shape[0] - 1) & (h.shape[0] - 2) or h.shape[0] < 3:
            raise TerrabenchError(f"tile heights must be (n+1)² with n a power of two >= 2, got shape {h.shape}")
        self.n = h.shape[0] - 1
        self.key = tile.key
        nodes = global_nodes(strategy.hf, self.n, strategy.beta)
        data, self.offsets = tile_node_block(nodes, int(tile.key.level), int(tile.key.tx), int(tile.key.ty), self.n)
        self.starts = level_starts(self.n)
        self.level_error, self.level_lo, self.level_hi = level_bounds(data, self.offsets, self.n, float(tile.spacing))
        self.heights = ctx.buffer(h.tobytes())
        self.nodes = ctx.buffer(data.tobytes())
        self.capacity = (self.n // 2) ** 2
        self.segments = ctx.buffer(reserve=max(4 * self.n, 8) * SEGMENT_WORDS * 4)
        self.commands = ctx.buffer(reserve=3 * COMMAND_WORDS * 4)
        self.found = ctx.buffer(reserve=(4 + self.capacity) * 4)
        self.writes = strategy.writes
        mesh = self.writes == "mesh"            # each strategy allocates only the output its draw reads
        self.leaves = ctx.buffer(reserve=(1 if mesh else self.capacity) * LEAF_WORDS * 4)
        self.mesh_vertices = ctx.buffer(reserve=(self.capacity if mesh else 1) * 9 * 16)
        self.mesh_indices = ctx.buffer(reserve=(self.capacity if mesh else 1) * 24 * 4)
        self.vaos = strategy.tile_arrays(self)

    @property
    def nbytes(self) -> int:
        """GPU bytes of the tile's textures and buffers, as the driver reports them."""
        return gl_bytes(self.heights, self.nodes, self.leaves, self.segments, self.commands, self.found,
                        self.mesh_vertices, self.mesh_indices)

    def release(self) -> None:
        """Free the GPU objects."""
        for v in self.vaos.values():
            v.release()
        for o in (self.leaves, self.mesh_vertices, self.mesh_indices, self.segments, self.commands, self.found,
                  self.nodes, self.heights):
            o.release()


class TileletSelection:
    """The part the two tilelet strategies share: terrain texture, the selection shader, per-tile GPU data."""

    kind = "raster"
    writes = "records"          # what the selection writes for the draw: leaf records or a mesh

    def __init__(self, ctx, hf, beta: float = DEFAULT_BETA):
        if not (0.0 < beta < 1.0):
            raise TerrabenchError(f"beta must lie in (0, 1), got {beta!r}")
        self.ctx, self.hf, self.beta = ctx, hf, float(beta)
        self.passes = tuple(compute_shader(ctx, "raster", "select.comp.glsl", {"PASS": k}) for k in (0, 1))
        self.texture = terrain_texture(ctx, hf)
        self.frame = ctx.buffer(reserve=4 * len(FRAME_FIELDS))

    @property
    def shared_nbytes(self) -> int:
        """GPU bytes shared by all tiles, as the driver reports them: colour texture, frame counters."""
        return gl_bytes(self.texture, self.frame)

    def upload(self, tile) -> SelectedTileletTile:
        """Put one tile on the GPU: heights, node errors and boxes, empty leaf buffers."""
        return SelectedTileletTile(self, tile)

    def tile_arrays(self, g: SelectedTileletTile) -> dict:
        """The vertex arrays a strategy draws a tile's leaves with (subclasses)."""
        raise NotImplementedError

    def set_selection(self, name: str, value) -> None:
        """Set a uniform of both selection passes (where the pass uses it)."""
        for prog in self.passes:
            set_uniform(prog, name, value)

    def select_leaves(self, view, items, tau: float, culling: bool = True, skirts: dict | None = None) -> None:
        """Run the leaf selection of every item for the view at tau pixels; fills each tile's commands.

        Per tile: pass 0 over its nodes lists the leaves, pass 1 (dispatched from their count) emits them.
        """
        if not (np.isfinite(tau) and tau > 0):
            raise TerrabenchError(f"tau must be finite and > 0 pixels, got {tau!r}")
        k_tau = float(view.pixels_per_radian) / float(tau)
        planes = view.frustum_planes_rel().astype(np.float32).tobytes()
        for prog in self.passes:
            if "planes" in prog:
                prog["planes"].write(planes)
        self.set_selection("k_tau", k_tau)
        self.set_selection("write_records", self.writes == "records")
        self.set_selection("write_mesh", self.writes == "mesh")
        self.set_selection("beta", self.beta)
        self.frame.write(np.zeros(len(FRAME_FIELDS), np.uint32).tobytes())
        self.frame.bind_to_storage_buffer(4)
        list_pass, emit_pass = self.passes
        for g, tile, sel in items:
            origin_rel = np.asarray(tile.origin, dtype=np.float64) - view.eye
            eye_local = view.eye - np.asarray(tile.origin, dtype=np.float64)
            first = int(g.starts[first_level(g, eye_local, k_tau)])
            for name, value in (("n_cells", int(g.n)), ("top", tile_levels(g.n) - 1),
                                ("offsets", _padded(g.offsets[:-1], 13)), ("starts", _padded(g.starts, 14)),
                                ("nb_delta", tuple(int(d) for d in sel.edge_deltas)),
                                ("origin_rel", tuple(origin_rel.astype(np.float32))), ("spacing", float(tile.spacing)),
                                ("cull", bool(culling) and not bool(sel.inside)),
                                ("skirt_edges", int((skirts or {}).get(sel.key, 0))),
                                ("skirt_bottom", skirt_bottom(tile, view)), ("first_id", first)):
                self.set_selection(name, value)
            g.commands.write(COMMANDS_BLANK)
            g.found.write(FOUND_BLANK)
            for binding, buf in ((0, g.nodes), (1, g.leaves), (2, g.commands), (3, g.segments), (5, g.heights),
                                 (6, g.found), (7, g.mesh_vertices), (8, g.mesh_indices)):
                buf.bind_to_storage_buffer(binding)
            list_pass.run(group_x=(int(g.starts[-1]) - first + _LOCAL - 1) // _LOCAL)
            self.ctx.memory_barrier()
            emit_pass.run_indirect(g.found)
        self.ctx.memory_barrier()

    def frame_counters(self) -> dict:
        """Counters of the last selection, summed over its tiles (one read of a small buffer)."""
        raw = np.frombuffer(self.frame.read(), dtype=np.uint32)
        return {f: int(v) for f, v in zip(FRAME_FIELDS, raw)}

    def release(self) -> None:
        """Free the selection shader, the texture and the counters."""
        for o in (*self.passes, self.texture, self.frame):
            if o is not None:
                o.release()
