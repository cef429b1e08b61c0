"""The ray-cast tile strategy on the GPU: per-tile height + max-mip textures, one box pass per tile.

A tile is 16-bit height codes (hybrid.tiles.quantize: exact on a 16-bit source's step, else range/65535 with
the error measured, reported per frame as ``quant_error_max_m``) in an R16UI (N+1)² texture, and its max
mipmap of codes without level 0 in an R16UI (N/2)² texture (raycast.maxmip): 2.67 bytes a sample for large
N, ``bytes_per_sample``. The shadow grid (the whole terrain for shadow rays) has the same form.

Satisfies ``hybrid.contract.TileStrategy``: ``upload(tile) -> GpuTile``, ``draw_tiles(target, view, items,
tau, **options) -> dict``, ``shared_nbytes``, ``release()``.
Each tile pass rasterizes the back faces of the tile's clipped bounding box; the fragment shader casts the
pixel-centre ray (from the camera basis, as View.pixel_dirs_eye), traverses the max mipmap in the tile's
texel space (mirrored so Dir_x, Dir_y >= 0), intersects the chosen reconstruction, shades the hit and writes
gl_FragDepth = clip.z / clip.w with the view's reversed-Z ``view_proj_rel``. Misses and capped rays discard.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import depth32f_texture, gl_bytes, gl_finish, gl_memory_barrier, is_software
from hybrid.gl.edges import TerrainEdges
from hybrid.gl.programs import program, register_include, set_uniform, write_uniform
from hybrid.gl.shading import resolve_mode
from hybrid.gl.textures import terrain_texture
from hybrid.tiles.quantize import quantize

from .maxmip import MaxMipBuilder, bytes_per_sample, level_count, tile_nbytes
from .options import MODES, RECONSTRUCTIONS, CastOptions, default_max_steps, prepass_default
from .tile_params import TILE_BLOCK, block_stride, outer_bits, tile_params, tile_row

STAT_FIELDS = ("rays", "hits", "steps", "max_steps", "capped", "shadow_rays", "shadow_steps", "shadow_capped")
STAT_SLOTS = 64          # copies of each tile's counters (one per screen bin, modulo)
STAT_STRIDE = 64         # bytes between copies (16 uints: one cache line, 8 used)
STAT_BIN_SHIFT = 6       # screen bins of 2^6 = 64 pixels a side
STATS_BINDING, TILE_PARAMS_BINDING = 0, 3     # storage binding of the counters, uniform binding of a tile's block
LAYOUT_DEFINES = {"STAT_SLOTS": STAT_SLOTS, "STAT_WORDS": STAT_STRIDE // 4, "STAT_BIN_SHIFT": STAT_BIN_SHIFT,
                  "STATS_BINDING": STATS_BINDING, "TILE_PARAMS_BINDING": TILE_PARAMS_BINDING}
"""The layout above as the shaders' defines (raycast.frag.glsl, tile_block.glsl): their only source of it."""


def _cube_back_face_triangles() -> np.ndarray:
    """36 unit-cube corners (float32), 12 triangles wound counter-clockwise seen from outside the cube."""
    quads = [((0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)),   # bottom, normal -z
             ((0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)),   # top, +z
             ((0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)),   # south, -y
             ((0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)),   # north, +y
             ((0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0)),   # west, -x
             ((1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1))]   # east, +x
    tris = []
    for a, b, c, d in quads:
        tris += [a, b, c, a, c, d]
    return np.array(tris, dtype=np.float32)


@dataclass
class GpuTile:
    """One tile on the GPU: R16UI (N+1)² height codes and their R16UI (N/2)² max mipmap (levels 1..log2 N);
    exact byte count; metres = offset + step * (code + base); quant_error: largest |height - dequantised| (m)."""

    heights: object
    maxmip: object
    n: int
    nbytes: int
    offset: float = 0.0
    step: float = 1.0
    base: int = 0
    quant_error: float = 0.0
    row: np.ndarray | None = None       # tile_row of the tile uploaded (None: a grid, not a tile)
    bounds: tuple = ()                  # that tile's clip, zmin and zmax, to tell it from a tile drawn in its place

    @property
    def bytes_per_sample(self) -> float:
        """GPU bytes per height sample held, max mipmap included: nbytes / (N+1)²."""
        return self.nbytes / (self.n + 1) ** 2

    def release(self) -> None:
        """Free both textures."""
        self.heights.release()
        self.maxmip.release()


@dataclass
class _Grid:
    """The whole terrain as one power-of-two grid, for shadow rays (built on the first shadowed draw)."""

    tex: GpuTile
    n: int
    ext: tuple
    zr: tuple
    nbytes: int


def outer_faces(clip, hf) -> int:
    """Bit mask of a tile's box sides lying on the terrain's outer boundary (W 1, E 2, S 4, N 8)."""
    return int(outer_bits([[float(v) for v in clip]], hf)[0])


class RaycastStrategy:
    """GPU ray caster of height-field tiles over maximum mipmaps (Dick et al. 2009) with Qu's reconstructions."""

    kind = "raycast"
    draw_options = frozenset(f.name for f in fields(CastOptions))

    def __init__(self, ctx, hf, **options):
        self.ctx, self.hf = ctx, hf
        register_include(ctx, "raycast/traverse", "raycast", "traverse.glsl")
        register_include(ctx, "raycast/tile_block", "raycast", "tile_block.glsl")
        self._prepass = prepass_default(is_software(ctx))
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
        self.prior = None                       # the frame's earlier passes, for occluded passes
        self.tile_buf = None                    # the frame's TileParams blocks (tile_params)
        self._stride = block_stride(ctx.info.get("GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT", 256))
        self._next_id = 1
        self.grid: _Grid | None = None
        self.last_tile_stats = np.zeros((0, len(STAT_FIELDS)), np.int64)

    # --- options and programs ---------------------------------------------------------------------
    def _check_mode(self, opts: CastOptions) -> str:
        return resolve_mode(self.hf, opts.mode, MODES)

    def _resolved(self, opts: CastOptions) -> CastOptions:
        """opts with a pre-pass left to the device (None) set to the device's default (prepass_default)."""
        return opts if opts.prepass is not None else opts.updated(prepass=self._prepass)

    def _program(self, opts: CastOptions, mode: str):
        opts = self._resolved(opts)
        key = (opts.reconstruction, opts.traversal, opts.lod is not None, opts.prepass, opts.stats, opts.shadows, mode,
               opts.occluders)
        if key not in self.programs:
            defines = {"RECON": RECONSTRUCTIONS.index(opts.reconstruction), "NAIVE": int(opts.traversal == "naive"),
                       "LOD": int(opts.lod is not None), "PREPASS": int(opts.prepass), "STATS": int(opts.stats),
                       "SHADOWS": int(opts.shadows), "MODE": MODES.index(mode), "OCCLUDERS": int(opts.occluders),
                       **LAYOUT_DEFINES}
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
        return gl_bytes(self.texture, self.cube, self.stats_buf, self.ids, self.tile_buf, *prior, *grid) + self.edges.nbytes

    # --- tiles ------------------------------------------------------------------------------------
    @staticmethod
    def bytes_per_sample(n: int) -> float:
        """GPU bytes per height sample of an n-cell tile, max mipmap included (the textures ``upload`` makes)."""
        return bytes_per_sample(n)

    def upload(self, tile) -> GpuTile:
        """Put a tile's (N+1)² heights on the GPU as 16-bit codes and build their max mipmap there."""
        g = self.upload_grid(tile.heights, getattr(tile, "source_step", None))
        g.row, g.bounds = tile_row(g, tile), (tile.clip, tile.zmin, tile.zmax)
        return g

    def _shadow_grid(self) -> _Grid:
        if self.grid is None:
            hf = self.hf
            h = np.asarray(hf.heights, dtype=np.float32)
            cells = max(h.shape) - 1
            n = 1 << max(1, int(np.ceil(np.log2(max(cells, 2)))))
            pad = np.pad(h, ((0, n + 1 - h.shape[0]), (0, n + 1 - h.shape[1])), mode="edge")
            g = self.upload_grid(pad, getattr(hf, "source_step", None))
            lo, hi = float(h.min()), float(h.max())
            self.grid = _Grid(g, n, (float(h.shape[1] - 1), float(h.shape[0] - 1)), (lo, hi), g.nbytes)
        return self.grid

    def upload_grid(self, heights: np.ndarray, source_step=None) -> GpuTile:
        """Heights (N+1)² (N a power of two >= 2; float32 metres relative to origin z) on the GPU as 16-bit codes
        (exact on ``source_step``, hybrid.tiles.quantize), with their max mipmap built there."""
        h = np.asarray(heights, dtype=np.float32)
        n = h.shape[0] - 1
        if h.ndim != 2 or h.shape[1] != h.shape[0] or n < 2 or n & (n - 1):
            raise TerrabenchError(f"tile heights must be (N+1, N+1) with N a power of two >= 2, got {h.shape}")
        qz = quantize(h, source_step)
        ht = self.ctx.texture((n + 1, n + 1), 1, np.ascontiguousarray(qz.q).tobytes(), dtype="u2")
        ht.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
        mm = self.builder.build(ht, n)
        return GpuTile(ht, mm, n, tile_nbytes(n), qz.offset, qz.step, qz.base, qz.error)

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
            self.prior = self.ctx.framebuffer(color_attachments=[self.ctx.texture(tuple(size), 4)], depth_attachment=depth)
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
        mode = self._check_mode(opts)
        prog, vao = self._program(opts, mode)
        W, H = int(view.width), int(view.height)
        if tuple(target.size) != (W, H):
            raise TerrabenchError(f"target size {tuple(target.size)} does not match the view's {W}x{H} pixels")
        self._view_uniforms(prog, view, opts)
        grid = self._shadow_uniforms(prog, opts) if opts.shadows else None
        self._stats_buffer(prog, W, len(items))
        if opts.occluders and items:
            self._occluder_uniforms(prog, target, view)
        id_fbo = self._id_framebuffer(prog, target, (W, H), len(items)) if opts.prepass and items else None
        self._cast(target, view, items, opts, vao, id_fbo)
        gl_memory_barrier(self.ctx)
        return self._counters(opts, items, grid)

    def _view_uniforms(self, prog, view, opts: CastOptions) -> None:
        """The view's, the terrain's and the textures' uniforms of the cast program (and the pre-pass's view)."""
        hf = self.hf
        W, H = int(view.width), int(view.height)
        vp = np.asarray(view.view_proj_rel, dtype=np.float64)
        write_uniform(prog, "view_proj_rel", vp.T.astype(np.float32).tobytes())
        self.prepass_prog["view_proj_rel"].write(vp.T.astype(np.float32).tobytes())
        write_uniform(prog, "cam_to_world", np.asarray(view.rotation(), np.float64).astype(np.float32).tobytes())
        t = float(view.tan_half_fov)
        set_uniform(prog, "ndc_scale", (t * W / H, t))
        set_uniform(prog, "viewport", (float(W), float(H)))
        set_uniform(prog, "near_plane", float(view.near))
        set_uniform(prog, "far_plane", float(view.far))
        lo, hi = hf.height_range
        set_uniform(prog, "hrange", (lo, hi))
        set_uniform(prog, "heat_max", float(opts.heat_max))
        if self.texture is not None:
            self.texture.use(2)
            set_uniform(prog, "tex", 2)
        set_uniform(prog, "hmap", 0)
        set_uniform(prog, "mmap", 1)
        self.edges.bind(prog, hf, view, 6)

    def _shadow_uniforms(self, prog, opts: CastOptions):
        """Bind the whole terrain's shadow grid and set its uniforms; the grid back."""
        hf = self.hf
        grid = self._shadow_grid()
        grid.tex.heights.use(3)
        grid.tex.maxmip.use(5)
        set_uniform(prog, "g_dq", (grid.tex.offset, grid.tex.step))
        set_uniform(prog, "g_dq_base", grid.tex.base)
        set_uniform(prog, "g_hmap", 3)
        set_uniform(prog, "g_mmap", 5)
        set_uniform(prog, "g_cells", grid.n)
        set_uniform(prog, "g_levels", level_count(grid.n) - 1)
        set_uniform(prog, "g_ext", grid.ext)
        set_uniform(prog, "g_zr", grid.zr)
        set_uniform(prog, "g_spacing", (hf.spacing_x, hf.spacing_y))
        set_uniform(prog, "g_max_steps", opts.max_steps or default_max_steps(grid.n))
        return grid

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
        self.ctx.copy_framebuffer(prior, target.fbo)       # depth (and colour) drawn so far this frame
        prior.depth_attachment.use(8)
        set_uniform(prog, "prior_depth", 8)
        n, f = float(view.near), float(view.far)
        set_uniform(prog, "depth_ab", (n / (f - n), n * f / (f - n)))

    def _id_framebuffer(self, prog, target, size: tuple[int, int], n_items: int):
        """The tile-ID pre-pass's framebuffer over the target's depth, its IDs texture bound for the cast pass."""
        ids = self._ids_texture(size)
        if self._next_id + n_items >= 2 ** 32 - 1:
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
            for k, (g, _tile, _sel) in enumerate(items):
                self.tile_buf.bind_to_uniform_block(TILE_PARAMS_BINDING, offset=k * self._stride,
                                                    size=TILE_BLOCK.itemsize)
                if id_fbo is not None:
                    id_fbo.use()
                    ctx.depth_func = ">"
                    self.prepass_vao.render()
                    target.fbo.use()
                    ctx.depth_func = ">"
                g.heights.use(0)
                g.maxmip.use(1)
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
        rows = np.stack([g.row if g.row is not None and g.bounds == (t.clip, t.zmin, t.zmax) else tile_row(g, t)
                         for g, t, _ in items]) if items else None
        blocks = tile_params(items, eye, self.hf, lod_scale, opts.max_steps, self._next_id, self._stride, rows)
        if self.tile_buf is None or self.tile_buf.size < blocks.nbytes:
            if self.tile_buf is not None:
                self.tile_buf.release()
            self.tile_buf = self.ctx.buffer(reserve=max(blocks.nbytes, 64 * self._stride))
        self.tile_buf.write(blocks.tobytes())

    def _counters(self, opts: CastOptions, items, grid) -> dict:
        """The frame's counters: rays, hits and steps summed over the tiles' copies (with ``stats``), and more."""
        n_items = len(items)
        counters = {"rays": 0, "hits": 0, "steps": 0, "max_steps": 0, "capped": 0}
        if opts.stats and n_items:
            gl_finish(self.ctx)                 # the wait lets other threads (the tile loader) run
            raw = np.frombuffer(self.stats_buf.read(size=STAT_SLOTS * STAT_STRIDE * n_items), dtype=np.uint32)
            raw = raw.reshape(n_items, STAT_SLOTS, STAT_STRIDE // 4)[:, :, :len(STAT_FIELDS)].astype(np.int64)
            st = raw.sum(axis=1)
            st[:, 3] = raw[:, :, 3].max(axis=1)
            self.last_tile_stats = st
            tot = st.sum(axis=0)
            counters = {f: int(tot[i]) for i, f in enumerate(STAT_FIELDS)}
            counters["max_steps"] = int(st[:, 3].max())
            counters["mean_steps"] = counters["steps"] / max(counters["rays"], 1)
            if not opts.shadows:
                for f in ("shadow_rays", "shadow_steps", "shadow_capped"):
                    counters.pop(f)
        counters["tiles_cast"] = n_items
        counters["quant_error_max_m"] = max((float(g.quant_error) for g, _t, _s in items), default=0.0)
        if grid is not None:
            counters["shadow_grid_bytes"] = grid.nbytes
            counters["shadow_quant_error_m"] = float(grid.tex.quant_error)
        return counters

    def release(self) -> None:
        """Free programs, buffers and textures (not the tiles: release those through their GpuTile)."""
        for prog, vao in self.programs.values():
            vao.release()
            prog.release()
        self.programs.clear()
        for o in (self.prepass_vao, self.prepass_prog, self.cube, self.stats_buf, self.texture, self.ids, self.edges,
                  self.tile_buf):
            if o is not None:
                o.release()
        if self.grid is not None:
            self.grid.tex.release()
            self.grid = None
        self._release_prior()
        self.builder.release()
