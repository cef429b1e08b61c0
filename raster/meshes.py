"""GPU meshes of the baselines: a vertex buffer of tile-local float32 positions and a uint32 index buffer.

Bytes per triangle of an indexed list: 12 bytes of indices (the paper's 96 bits) plus the vertex buffer
(12 bytes a vertex) shared between triangles; each tile also holds its skirts (raster.mesh_skirts).

The baselines draw each selected tile at its own level without stitching (by design: they measure what a plain
mesh per tile costs). Seams between tiles whose surfaces differ along a shared side are closed by skirts hung
from those sides, deep as the measured difference (draw option ``seam_skirts``, on by default).
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import gl_bytes
from hybrid.gl.edges import TerrainEdges
from hybrid.gl.programs import program, set_uniform
from hybrid.gl.shading import resolve_mode
from hybrid.gl.textures import terrain_texture
from hybrid.terrain.edges import edge_profiles

from .edit import stale_tiles
from .mesh_skirts import SeamDepths, SkirtMesh, mesh_border_edges, rays_may_start_under
from .options import MeshOptions
from .shading import MODES
from .tileblock import BLOCK_DEFINES, TileBlocks, register_tile_block, tile_blocks

GL_CLIP_DISTANCE0 = 0x3000


class MeshTile:
    """One tile's mesh on the GPU: vertices (v, 3) float32 metres (tile-local), faces (f, 3) uint32."""

    def __init__(self, ctx, prog, key, vertices: np.ndarray, faces: np.ndarray, skirt: SkirtMesh | None = None):
        v = np.ascontiguousarray(vertices, dtype=np.float32)
        f = np.ascontiguousarray(faces, dtype=np.uint32)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
            raise TerrabenchError(f"mesh needs vertices (v, 3) and faces (f, 3), got {v.shape} and {f.shape}")
        if f.size and int(f.max()) >= len(v):
            raise TerrabenchError(f"face index {int(f.max())} out of range for {len(v)} vertices")
        self.key = key
        self.vbo = ctx.buffer(v.tobytes())
        self.ibo = ctx.buffer(f.tobytes())
        self.vao = ctx.vertex_array(prog, [(self.vbo, "3f", "a_pos")], index_buffer=self.ibo, index_element_size=4)
        self.triangles = int(len(f))
        self.skirt = skirt

    @property
    def nbytes(self) -> int:
        """Exact GPU bytes: vertex buffer + index buffer, and the skirts'."""
        return int(self.vbo.size + self.ibo.size) + (self.skirt.nbytes if self.skirt is not None else 0)

    def release(self) -> None:
        """Free the GPU objects."""
        for o in (self.vao, self.ibo, self.vbo, self.skirt):
            if o is not None:
                o.release()


class MeshStrategyBase:
    """Shared drawing of per-tile indexed meshes and their skirts; subclasses build the mesh of a tile in
    ``mesh_of`` (and may give its border edges in ``border_edges``)."""

    kind = "raster"
    options_type = MeshOptions
    draw_options = frozenset(f.name for f in fields(MeshOptions))

    def __init__(self, ctx, hf):
        self.ctx, self.hf = ctx, hf
        register_tile_block(ctx)
        self.blocks = TileBlocks(ctx)
        self.prog = program(ctx, "raster", "mesh.vert.glsl", "tilelet.frag.glsl", defines=BLOCK_DEFINES)
        self.skirt_prog = program(
            ctx,
            "raster",
            "mesh.vert.glsl",
            "tilelet.frag.glsl",
            defines={"SEAM_SKIRT": 1, "SKIRT_PROGRAM": 1, **BLOCK_DEFINES},
        )
        self.texture = terrain_texture(ctx, hf)
        self.edges = TerrainEdges(ctx, hf)  # which rays start under the sheet (skirts rise for those)
        self.edge_tops = edge_profiles(hf.heights).max(axis=1)
        self.depths = SeamDepths(hf.height_range[0])

    def follow_edit(self, change, resident, tile) -> tuple[int, list]:
        """Follow an edit (``hybrid.contract.EditFollowing``): the resident tiles it changed, to upload again."""
        return stale_tiles(change, resident)

    @property
    def shared_nbytes(self) -> int:
        """GPU bytes shared by all tiles as the driver reports them (the colour texture with mipmaps, the tile
        blocks, the terrain's edge profiles)."""
        return gl_bytes(self.texture, self.blocks.buffer) + self.edges.nbytes

    def mesh_of(self, tile) -> tuple[np.ndarray, np.ndarray]:
        """(vertices, faces) of a tile, tile-local metres."""
        raise NotImplementedError

    def border_edges(self, tile, vertices: np.ndarray, faces: np.ndarray) -> list[np.ndarray]:
        """Per side W, E, S, N: the mesh's border edges along it as (m, 2) vertex-index pairs."""
        h = np.asarray(tile.heights)
        extent = ((h.shape[1] - 1) * tile.spacing_x, (h.shape[0] - 1) * tile.spacing_y)
        return mesh_border_edges(np.asarray(vertices, dtype=np.float64), faces, extent)

    def upload(self, tile) -> MeshTile:
        """Build the tile's mesh and skirts and put them on the GPU."""
        v, f = self.mesh_of(tile)
        skirt = SkirtMesh(self.ctx, self.skirt_prog, v, self.border_edges(tile, v, f), tile)
        return MeshTile(self.ctx, self.prog, tile.key, v, f, skirt)

    def set_frame_uniforms(self, view, mode: str) -> None:
        """The view's and shading's uniforms of both programs; the terrain texture on unit 1."""
        vp = view.view_proj_rel.T.astype(np.float32).tobytes()
        for prog in (self.prog, self.skirt_prog):
            prog["view_proj_rel"].write(vp)
            prog["mode"].value = MODES[mode]
            set_uniform(prog, "wireframe", False)
            prog["hrange"].value = tuple(float(v) for v in self.hf.height_range)
            if self.texture is not None:
                prog["tex"].value = 1
        if self.texture is not None:
            self.texture.use(1)

    def draw_tiles(
        self,
        target,
        view,
        items,
        tau: float | None = None,
        mode: str | None = None,
        wireframe: bool = False,
        seam_skirts: bool = True,
    ) -> dict:
        """Draw (mesh_tile, tile, selected) items into target, then (``seam_skirts``, not in wireframe) their
        skirts; counters: triangles (GL query and CPU sum, meshes only), skirt_triangles (issued)."""
        mode = resolve_mode(self.hf, mode, MODES)
        ctx = self.ctx
        self.set_frame_uniforms(view, mode)
        self.blocks.write(tile_blocks(self.hf, view, items, unit_spacing=True))  # positions are metres
        target.use()
        ctx.wireframe = bool(wireframe)
        for i in range(4):
            ctx.enable_direct(GL_CLIP_DISTANCE0 + i)
        query = ctx.query(primitives=True)
        cpu = skirts = 0
        try:
            with query:
                for i, (g, _tile, _sel) in enumerate(items):
                    self.blocks.bind(i)
                    g.vao.render(ctx.TRIANGLES)
                    cpu += g.triangles
        finally:
            ctx.wireframe = False
            for i in range(4):
                ctx.disable_direct(GL_CLIP_DISTANCE0 + i)
        skirts = self.draw_seam_skirts(target, view, items) if seam_skirts and not wireframe else 0
        return {"triangles": int(query.primitives), "triangles_cpu": cpu, "skirt_triangles": skirts}

    def draw_seam_skirts(self, target, view, items) -> int:
        """Draw the skirts of the items the last ``draw_tiles`` call drew (its tile blocks and uniforms) into
        target: hanging below the edges (``SeamDepths``), and rising above them too where some rays may start
        under the sheet; triangles issued."""
        ctx, prog = self.ctx, self.skirt_prog
        depths = self.depths(items)
        self.edges.bind(prog, self.hf, view, 6)
        if self.texture is not None:
            self.texture.use(1)
        target.use()
        drawn = 0
        for i in range(4):
            ctx.enable_direct(GL_CLIP_DISTANCE0 + i)
        try:
            for under in (False, True) if rays_may_start_under(self.hf, view, self.edge_tops) else (False,):
                prog["under_pass"].value = under
                for i, (g, _tile, _sel) in enumerate(items):
                    if depths[i].any():
                        self.blocks.bind(i)
                        prog["skirt_depth"].value = tuple(float(-d if under else d) for d in depths[i])
                        drawn += g.skirt.draw(depths[i])
        finally:
            for i in range(4):
                ctx.disable_direct(GL_CLIP_DISTANCE0 + i)
        return drawn

    def release(self) -> None:
        """Free the programs, the terrain texture, the edge profiles and the tile blocks."""
        self.blocks.release()
        self.edges.release()
        for o in (self.prog, self.skirt_prog, self.texture):
            if o is not None:
                o.release()
