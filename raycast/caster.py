"""The ray-cast tile strategy on the GPU: per-tile height texture + max-mip buffer, one box pass per tile.

A tile is 16-bit height codes (hybrid.tiles.quantize: exact on a 16-bit source's step, else range/65535 with
the error measured, reported per frame as ``quant_error_max_m``) in an R16UI (N+1)² texture, and its max
mipmap of codes without level 0 in a storage buffer (raycast.mip_buffer): 2.67 bytes a sample for large N,
``bytes_per_sample``. The shadow grid (the whole terrain for shadow rays) keeps its max mipmap in an R16UI
(N/2)² texture with log2 N levels (raycast.maxmip), since it can outgrow a storage block.

Satisfies ``hybrid.contract.TileStrategy``: ``upload(tile) -> GpuTile``, ``draw_tiles(target, view, items,
tau, **options) -> dict``, ``shared_nbytes``, ``release()``.
Each tile pass rasterizes the back faces of the tile's clipped bounding box; the fragment shader casts the
pixel-centre ray (from the camera basis, as View.pixel_dirs_eye), traverses the max mipmap in the tile's
texel space (mirrored so Dir_x, Dir_y >= 0), intersects the chosen reconstruction, shades the hit and writes
gl_FragDepth = clip.z / clip.w with the view's reversed-Z ``view_proj_rel``. Misses and capped rays discard.
"""

from __future__ import annotations

from dataclasses import fields
from typing import TYPE_CHECKING

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import depth32f_texture, gl_bytes, gl_finish, gl_memory_barrier
from hybrid.gl.edges import TerrainEdges
from hybrid.gl.programs import program, register_include, set_uniform
from hybrid.gl.shading import resolve_mode
from hybrid.gl.textures import terrain_texture
from hybrid.terrain.edges import may_start_under

from .cast_stats import (
    LAYOUT_DEFINES,
    MIPS_BINDING,
    STAT_BIN_SHIFT,
    STAT_FIELDS,
    STAT_SLOTS,
    STAT_STRIDE,
    STATS_BINDING,
    TILE_PARAMS_BINDING,
    frame_counters,
    read_tile_stats,
)
from .cast_uniforms import shadow_uniforms, view_uniforms
from .edit import follow_tile, local_window
from .gpu_tile import GpuTile, HostTile, ShadowGrid, prepare_heights, shadow_grid, upload_heights, upload_prepared
from .maxmip import MaxMipBuilder, bytes_per_sample
from .options import MODES, RECONSTRUCTIONS, CastOptions, prepass_default
from .tile_params import TILE_BLOCK, block_stride, outer_bits, tile_params, tile_row

if TYPE_CHECKING:
    import moderngl


def _cube_back_face_triangles() -> np.ndarray:
    """36 unit-cube corners (float32), 12 triangles wound counter-clockwise seen from outside the cube."""
    quads = [
        ((0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)),  # bottom, normal -z
        ((0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)),  # top, +z
        ((0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)),  # south, -y
        ((0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)),  # north, +y
        ((0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0)),  # west, -x
        ((1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)),
    ]  # east, +x
    tris = []
    for a, b, c, d in quads:
        tris += [a, b, c, a, c, d]
    return np.array(tris, dtype=np.float32)


def outer_faces(clip, hf) -> int:
    """Bit mask of a tile's box sides lying on the terrain's outer boundary (W 1, E 2, S 4, N 8)."""
    return int(outer_bits(np.array([[float(v) for v in clip]]), hf)[0])


class RaycastStrategy:
    """GPU ray caster of height-field tiles over maximum mipmaps (Dick et al. 2009) with Qu's reconstructions."""

    kind = "raycast"
    options_type = CastOptions
    draw_options = frozenset(f.name for f in fields(CastOptions))

    def __init__(self, ctx, hf, **options):
        self.ctx, self.hf = ctx, hf
        register_include(ctx, "raycast/traverse", "raycast", "traverse.glsl")
        register_include(ctx, "raycast/tile_block", "raycast", "tile_block.glsl")
        self._prepass = prepass_default()
        self.options = self._resolved(CastOptions().updated(**options))
        self._check_mode(self.options)
        self.builder = MaxMipBuilder(ctx)
        self.cube = ctx.buffer(_cube_back_face_triangles().tobytes())
        self.prepass_prog = program(ctx, "raycast", "box.vert.glsl", "prepass.frag.glsl", defines=LAYOUT_DEFINES)
        self.prepass_vao = ctx.vertex_array(self.prepass_prog, [(self.cube, "3f", "corner")])
        self.programs: dict = {}
        self.texture = terrain_texture(ctx, hf)
        self.stats_buf = ctx.buffer(reserve=STAT_SLOTS * STAT_STRIDE)
        self.edges = TerrainEdges(ctx, hf)
        self.ids = None
        self.prior = None  # the frame's earlier passes, for occluded passes
        self.tile_buf: moderngl.Buffer | None = None  # the frame's TileParams blocks (tile_params)
        self._stride = block_stride(ctx.info.get("GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT", 256))
        self._next_id = 1
        self.grid: ShadowGrid | None = None
        self.last_tile_stats = np.zeros((0, len(STAT_FIELDS)), np.int64)

    # --- options and programs ---------------------------------------------------------------------
    def _check_mode(self, opts: CastOptions) -> str:
        return resolve_mode(self.hf, opts.mode, MODES)

    def _resolved(self, opts: CastOptions) -> CastOptions:
        """opts with the pre-pass left to the default (None) set to it (prepass_default)."""
        return opts if opts.prepass is not None else opts.updated(prepass=self._prepass)

    def _program(self, opts: CastOptions, mode: str, under: bool = True):
        """The (program, box vertex array) of the options and mode; ``under``: whether some of its rays may start
        under the terrain sheet (without, the shader takes none to)."""
        opts = self._resolved(opts)
        assert opts.prepass is not None  # _resolved chose the device's default
        key = (
            under,
            opts.reconstruction,
            opts.traversal,
            opts.lod is not None,
            opts.prepass,
            opts.stats,
            opts.shadows,
            mode,
            bool(opts.occluders),
            opts.heights,
        )
        if key not in self.programs:
            defines = {
                "RECON": RECONSTRUCTIONS.index(opts.reconstruction),
                "NAIVE": int(opts.traversal == "naive"),
                "LOD": int(opts.lod is not None),
                "PREPASS": int(opts.prepass),
                "STATS": int(opts.stats),
                "SHADOWS": int(opts.shadows),
                "MODE": MODES.index(mode),
                "OCCLUDERS": int(bool(opts.occluders)),
                "UNDER": int(under),
                "HF32": int(opts.heights == "float32"),
                **LAYOUT_DEFINES,
            }
            prog = program(self.ctx, "raycast", "box.vert.glsl", "raycast.frag.glsl", defines=defines)
            vao = self.ctx.vertex_array(prog, [(self.cube, "3f", "corner")])
            self.programs[key] = (prog, vao)
        return self.programs[key]

    @property
    def shared_nbytes(self) -> int:
        """GPU bytes held for all tiles as the driver reports them: colour texture, box, counters, tile IDs,
        the copy of a frame's earlier passes, terrain edges, shadow grid."""
        grid = (self.grid.tex.heights, self.grid.tex.maxmip) if self.grid is not None else ()
        prior = (*self.prior.color_attachments, self.prior.depth_attachment) if self.prior is not None else ()
        return (
            gl_bytes(self.texture, self.cube, self.stats_buf, self.ids, self.tile_buf, *prior, *grid)
            + self.edges.nbytes
        )

    # --- tiles ------------------------------------------------------------------------------------
    @staticmethod
    def bytes_per_sample(n: int) -> float:
        """GPU bytes per height sample of an n-cell tile of 16-bit codes, max mipmap included (the textures
        ``upload`` makes; twice that for ``heights='float32'`` tiles)."""
        return bytes_per_sample(n)

    host_product = "raycast.codes"  # the name of what host_prepare makes of a tile (StorePyramid.derive)

    def host_prepare(self, heights: np.ndarray, source_step=None, key=None) -> HostTile:
        """The CPU part of a tile's upload, which a store's loader thread runs ahead: its 16-bit codes (or float32
        metres, with ``heights='float32'``) and their max mipmap (of its samples alone: ``key`` is not read)."""
        return prepare_heights(heights, source_step, self.options.heights)

    def upload(self, tile) -> GpuTile:
        """Put a tile's (N+1)² heights on the GPU as 16-bit codes (or float32 metres) with their max mipmap, made
        on the host (taken from what the store's loader thread made of them, ``tile.host``, when it did)."""
        host = getattr(tile, "host", {}).pop(self.host_product, None)
        if host is None:
            host = self.host_prepare(tile.heights, getattr(tile, "source_step", None))
        g = upload_prepared(self.ctx, host)
        g.row, g.bounds = tile_row(g, tile), (tile.clip, tile.zmin, tile.zmax)
        return g

    def _shadow_grid(self) -> ShadowGrid:
        if self.grid is None:
            self.grid = shadow_grid(self.hf, self.upload_grid)
        return self.grid

    def upload_grid(self, heights: np.ndarray, source_step=None) -> GpuTile:
        """Heights (N+1)² (N a power of two >= 2; float32 metres relative to origin z) on the GPU as 16-bit codes
        (exact on ``source_step``, hybrid.tiles.quantize), with their max mipmap built there."""
        return upload_heights(self.ctx, self.builder, heights, source_step)

    def _ids_texture(self, size):
        if self.ids is None or self.ids.size != tuple(size):
            if self.ids is not None:
                self.ids.release()
            self.ids = self.ctx.texture(tuple(size), 1, dtype="u4")
            self.ids.write(np.zeros(size[0] * size[1], np.uint32).tobytes())
            self.ids.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            self._next_id = 1
        return self.ids

    def _prior_target(self, size):
        """A colour + depth framebuffer of the viewport's size (made on first use): the copy of what a frame's
        earlier passes drew, read as a texture by an occluded pass."""
        if self.prior is None or self.prior.size != tuple(size):
            self._release_prior()
            depth = depth32f_texture(self.ctx, tuple(size))
            depth.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            self.prior = self.ctx.framebuffer(
                color_attachments=[self.ctx.texture(tuple(size), 4)], depth_attachment=depth
            )
        return self.prior

    def _release_prior(self) -> None:
        if self.prior is not None:
            for a in (*self.prior.color_attachments, self.prior.depth_attachment, self.prior):
                a.release()
            self.prior = None

    # --- drawing ----------------------------------------------------------------------------------
    def draw_tiles(self, target, view, items, tau: float | None = None, **options) -> dict:
        """Ray cast the (gpu_tile, tile, selected) items, front to back, into the bound target for the view.

        ``tau`` (px) is the frame's bound; the caster refines to it only when the ``lod`` option asks.
        """
        opts = self._resolved(self.options.updated(**options))
        if opts.heights != self.options.heights:
            raise TerrabenchError(
                f"heights={opts.heights!r} asked of a caster whose tiles are {self.options.heights!r} "
                "(the tiles' format is fixed when the strategy is made)"
            )
        mode = self._check_mode(opts)
        prog, vao = self._program(opts, mode, may_start_under(self.hf, view.eye))
        W, H = int(view.width), int(view.height)
        if tuple(target.size) != (W, H):
            raise TerrabenchError(f"target size {tuple(target.size)} does not match the view's {W}x{H} pixels")
        view_uniforms(prog, self.prepass_prog, view, self.hf, self.texture, self.edges, opts.heat_max)
        grid = self._shadow_grid() if opts.shadows else None
        if grid is not None:
            shadow_uniforms(prog, grid, self.hf, opts.max_steps)
        self._stats_buffer(prog, W, len(items))
        if opts.occluders and items:
            self._occluder_uniforms(prog, target, view)
        id_fbo = self._id_framebuffer(prog, target, (W, H), len(items)) if opts.prepass and items else None
        self._cast(target, view, items, opts, vao, id_fbo)
        gl_memory_barrier(self.ctx)
        return self._counters(opts, items, grid)

    def _stats_buffer(self, prog, width: int, n_items: int) -> None:
        """The per-tile counters' buffer, cleared and bound, large enough for ``n_items`` tiles."""
        set_uniform(prog, "stat_bins_x", -(-width >> STAT_BIN_SHIFT))
        need = STAT_SLOTS * STAT_STRIDE * max(n_items, 1)
        if self.stats_buf.size < need:
            self.stats_buf.release()
            self.stats_buf = self.ctx.buffer(reserve=need)
        self.stats_buf.clear()
        self.stats_buf.bind_to_storage_buffer(STATS_BINDING)

    def _occluder_uniforms(self, prog, target, view) -> None:
        """A copy of the depth drawn so far this frame, bound for the rays to stop behind it."""
        prior = self._prior_target(tuple(target.size))
        self.ctx.copy_framebuffer(prior, target.fbo)  # depth (and colour) drawn so far this frame
        prior.depth_attachment.use(8)
        set_uniform(prog, "prior_depth", 8)
        n, f = float(view.near), float(view.far)
        set_uniform(prog, "depth_ab", (n / (f - n), n * f / (f - n)))

    def _id_framebuffer(self, prog, target, size: tuple[int, int], n_items: int):
        """The tile-ID pre-pass's framebuffer over the target's depth, its IDs texture bound for the cast pass."""
        ids = self._ids_texture(size)
        if self._next_id + n_items >= 2**32 - 1:
            ids.write(np.zeros(size[0] * size[1], np.uint32).tobytes())
            self._next_id = 1
        ids.use(4)
        set_uniform(prog, "ids", 4)
        id_fbo = self.ctx.framebuffer(color_attachments=[ids], depth_attachment=target.depth)
        id_fbo.depth_mask = False
        return id_fbo

    def _cast(self, target, view, items, opts: CastOptions, vao, id_fbo) -> None:
        """Draw every item's box (after its pre-pass, with one), front faces culled, its tile block bound."""
        ctx = self.ctx
        ctx.enable(ctx.CULL_FACE)
        ctx.front_face = "ccw"
        ctx.cull_face = "front"
        try:
            self._tile_blocks(view, items, opts)
            assert self.tile_buf is not None  # _tile_blocks made it
            for k, (g, _tile, _sel) in enumerate(items):
                self.tile_buf.bind_to_uniform_block(
                    TILE_PARAMS_BINDING, offset=k * self._stride, size=TILE_BLOCK.itemsize
                )
                if id_fbo is not None:
                    id_fbo.use()
                    ctx.depth_func = ">"
                    self.prepass_vao.render()
                    target.fbo.use()
                    ctx.depth_func = ">"
                g.heights.use(0)
                g.maxmip.bind_to_storage_buffer(MIPS_BINDING)
                vao.render()
        finally:
            ctx.disable(ctx.CULL_FACE)
            ctx.cull_face = "back"
            if id_fbo is not None:
                self._next_id += len(items)
                target.fbo.use()
                id_fbo.release()

    def _tile_blocks(self, view, items, opts: CastOptions) -> None:
        """Write every item's tile block (``raycast.tile_params``) into the tile buffer, grown as needed."""
        K = float(view.height) / (2.0 * float(view.tan_half_fov))
        lod_scale = K / float(opts.lod) if opts.lod else 0.0
        eye = np.asarray(view.eye, dtype=np.float64)
        # a tile drawn for a missing one (hybrid.uploads) has that one's clip and heights: its row is made here
        rows = (
            np.stack(
                [
                    g.row if g.row is not None and g.bounds == (t.clip, t.zmin, t.zmax) else tile_row(g, t)
                    for g, t, _ in items
                ]
            )
            if items
            else None
        )
        blocks = tile_params(items, eye, self.hf, lod_scale, opts.max_steps, self._next_id, self._stride, rows)
        if self.tile_buf is None or self.tile_buf.size < blocks.nbytes:
            if self.tile_buf is not None:
                self.tile_buf.release()
            self.tile_buf = self.ctx.buffer(reserve=max(blocks.nbytes, 64 * self._stride))
        self.tile_buf.write(blocks.tobytes())

    def _counters(self, opts: CastOptions, items, grid) -> dict:
        """The frame's counters (``raycast.cast_stats.frame_counters``); with ``stats``, each tile's kept in
        ``last_tile_stats``."""
        if not (opts.stats and items):
            return frame_counters(None, opts, items, grid)
        gl_finish(self.ctx)  # the wait lets other threads (the tile loader) run
        self.last_tile_stats = read_tile_stats(self.stats_buf, len(items))
        return frame_counters(self.last_tile_stats, opts, items, grid)

    def follow_edit(self, change, resident, tile) -> tuple[int, list]:
        """Follow an edit (``hybrid.contract.EditFollowing``): each touched resident tile's codes and max-mip texels
        over its changed samples, in place; the terrain's edge profiles when the edit reaches its border, and the
        shadow grid made again when next used. Nothing to upload again."""
        done = 0
        for key, gpu in resident:
            if key not in change.tiles:
                continue  # neither its samples nor its bounds changed
            t = tile(key)
            local = local_window(change.window, key, change.tile_size, self.hf.rows, self.hf.cols)
            if local.empty and (not gpu.bounds or tuple(gpu.bounds[1:]) == (t.zmin, t.zmax)):
                continue
            follow_tile(gpu, t, local)
            done += 1
        w = change.window
        if w.i0 == 0 or w.j0 == 0 or w.i1 == self.hf.rows or w.j1 == self.hf.cols:
            self.edges.release()
            self.edges = TerrainEdges(self.ctx, self.hf)
        if self.grid is not None:  # the shadow rays' whole grid: made again when next used
            self.grid.tex.release()
            self.grid = None
        return done, []

    def release(self) -> None:
        """Free programs, buffers and textures (not the tiles: release those through their GpuTile)."""
        for prog, vao in self.programs.values():
            vao.release()
            prog.release()
        self.programs.clear()
        for o in (
            self.prepass_vao,
            self.prepass_prog,
            self.cube,
            self.stats_buf,
            self.texture,
            self.ids,
            self.edges,
            self.tile_buf,
        ):
            if o is not None:
                o.release()
        if self.grid is not None:
            self.grid.tex.release()
            self.grid = None
        self._release_prior()
        self.builder.release()
