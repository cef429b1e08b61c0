"""GPU-resident tilelet quadtrees: what a tile keeps on the GPU, and the per-frame leaf selection (compute).

At upload a tile gets its heights (R32F texture), its node errors and boxes with a one-node apron
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


def level_starts(n: int) -> np.ndarray:
    """Index of the first node of each local level among a tile's own nodes (levels + 1 entries)."""
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
        self.heights = ctx.texture((self.n + 1, self.n + 1), 1, h.tobytes(), dtype="f4")
        self.heights.filter = (ctx.NEAREST, ctx.NEAREST)
        self.nodes = ctx.buffer(data.tobytes())
        self.capacity = (self.n // 2) ** 2
        self.leaves = ctx.buffer(reserve=self.capacity * LEAF_WORDS * 4)
        self.segments = ctx.buffer(reserve=max(4 * self.n, 8) * SEGMENT_WORDS * 4)
        self.commands = ctx.buffer(reserve=3 * COMMAND_WORDS * 4)
        self.vaos = strategy.tile_arrays(self)

    @property
    def nbytes(self) -> int:
        """GPU bytes of the tile's textures and buffers, as the driver reports them."""
        return gl_bytes(self.heights, self.nodes, self.leaves, self.segments, self.commands)

    def release(self) -> None:
        """Free the GPU objects."""
        for v in self.vaos.values():
            v.release()
        for o in (self.leaves, self.segments, self.commands, self.nodes, self.heights):
            o.release()


class TileletSelection:
    """The part the two tilelet strategies share: terrain texture, the selection shader, per-tile GPU data."""

    kind = "raster"

    def __init__(self, ctx, hf, beta: float = DEFAULT_BETA):
        if not (0.0 < beta < 1.0):
            raise TerrabenchError(f"beta must lie in (0, 1), got {beta!r}")
        self.ctx, self.hf, self.beta = ctx, hf, float(beta)
        self.select = compute_shader(ctx, "raster", "select.comp.glsl")
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

    def select_leaves(self, view, items, tau: float, culling: bool = True, skirts: dict | None = None) -> None:
        """Run the leaf selection of every item for the view at tau pixels; fills each tile's commands."""
        if not (np.isfinite(tau) and tau > 0):
            raise TerrabenchError(f"tau must be finite and > 0 pixels, got {tau!r}")
        prog = self.select
        k_tau = float(view.pixels_per_radian) / float(tau)
        prog["planes"].write(view.frustum_planes_rel().astype(np.float32).tobytes())
        set_uniform(prog, "k_tau", k_tau)
        set_uniform(prog, "beta", self.beta)
        set_uniform(prog, "heights", 0)
        self.frame.write(np.zeros(len(FRAME_FIELDS), np.uint32).tobytes())
        self.frame.bind_to_storage_buffer(4)
        blank = np.zeros(3 * COMMAND_WORDS, np.uint32)
        blank[[CMD_POINTS * COMMAND_WORDS + 1, CMD_TEMPLATE * COMMAND_WORDS, CMD_SKIRTS * COMMAND_WORDS]] = (1, 24, 6)
        for g, tile, sel in items:
            top = tile_levels(g.n) - 1
            origin_rel = np.asarray(tile.origin, dtype=np.float64) - view.eye
            g.commands.write(blank.tobytes())
            set_uniform(prog, "n_cells", int(g.n))
            set_uniform(prog, "top", top)
            set_uniform(prog, "offsets", _padded(g.offsets[:-1], 13))
            set_uniform(prog, "starts", _padded(g.starts, 14))
            set_uniform(prog, "nb_delta", tuple(int(d) for d in sel.edge_deltas))
            set_uniform(prog, "origin_rel", tuple(origin_rel.astype(np.float32)))
            set_uniform(prog, "spacing", float(tile.spacing))
            set_uniform(prog, "cull", bool(culling) and not bool(sel.inside))
            set_uniform(prog, "skirt_edges", int((skirts or {}).get(sel.key, 0)))
            set_uniform(prog, "skirt_bottom", skirt_bottom(tile, view))
            g.heights.use(0)
            g.nodes.bind_to_storage_buffer(0)
            g.leaves.bind_to_storage_buffer(1)
            g.commands.bind_to_storage_buffer(2)
            g.segments.bind_to_storage_buffer(3)
            eye_local = view.eye - np.asarray(tile.origin, dtype=np.float64)
            first = int(g.starts[first_level(g, eye_local, k_tau)])
            set_uniform(prog, "first_id", first)
            prog.run(group_x=(int(g.starts[-1]) - first + _LOCAL - 1) // _LOCAL)
        self.ctx.memory_barrier()

    def frame_counters(self) -> dict:
        """Counters of the last selection, summed over its tiles (one read of a small buffer)."""
        raw = np.frombuffer(self.frame.read(), dtype=np.uint32)
        return {f: int(v) for f, v in zip(FRAME_FIELDS, raw)}

    def release(self) -> None:
        """Free the selection shader, the texture and the counters."""
        for o in (self.select, self.texture, self.frame):
            if o is not None:
                o.release()
