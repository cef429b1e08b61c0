"""GPU meshes of the baselines: a vertex buffer of tile-local float32 positions and a uint32 index buffer.

Bytes per triangle of an indexed list: 12 bytes of indices (the paper's 96 bits) plus the vertex buffer
(12 bytes a vertex) shared between triangles.
"""
from __future__ import annotations

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import gl_bytes
from hybrid.gl.programs import program, set_uniform
from hybrid.gl.shading import resolve_mode
from hybrid.gl.textures import terrain_texture

from .shading import MODES
from .tileblock import BLOCK_DEFINES, TileBlocks, register_tile_block, tile_blocks

GL_CLIP_DISTANCE0 = 0x3000


class MeshTile:
    """One tile's mesh on the GPU: vertices (v, 3) float32 metres (tile-local), faces (f, 3) uint32."""

    def __init__(self, ctx, prog, key, vertices: np.ndarray, faces: np.ndarray):
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

    @property
    def nbytes(self) -> int:
        """Exact GPU bytes: vertex buffer + index buffer."""
        return int(self.vbo.size + self.ibo.size)

    def release(self) -> None:
        """Free the GPU objects."""
        for o in (self.vao, self.ibo, self.vbo):
            o.release()


class MeshStrategyBase:
    """Shared drawing of per-tile indexed meshes; subclasses build the mesh of a tile in ``mesh_of``."""

    kind = "raster"
    draw_options = frozenset({"mode", "wireframe"})

    def __init__(self, ctx, hf):
        self.ctx, self.hf = ctx, hf
        register_tile_block(ctx)
        self.blocks = TileBlocks(ctx)
        self.prog = program(ctx, "raster", "mesh.vert.glsl", "tilelet.frag.glsl", defines=BLOCK_DEFINES)
        self.texture = terrain_texture(ctx, hf)

    @property
    def shared_nbytes(self) -> int:
        """GPU bytes shared by all tiles as the driver reports them (the colour texture with mipmaps)."""
        return gl_bytes(self.texture, self.blocks.buffer)

    def mesh_of(self, tile) -> tuple[np.ndarray, np.ndarray]:
        """(vertices, faces) of a tile, tile-local metres."""
        raise NotImplementedError

    def upload(self, tile) -> MeshTile:
        """Build the tile's mesh and put it on the GPU."""
        v, f = self.mesh_of(tile)
        return MeshTile(self.ctx, self.prog, tile.key, v, f)

    def draw_tiles(self, target, view, items, tau: float | None = None, mode: str | None = None,
                   wireframe: bool = False) -> dict:
        """Draw (mesh_tile, tile, selected) items into target; counters: triangles (GL query and CPU sum)."""
        mode = resolve_mode(self.hf, mode, MODES)
        ctx, prog = self.ctx, self.prog
        prog["view_proj_rel"].write(view.view_proj_rel.T.astype(np.float32).tobytes())
        prog["mode"].value = MODES[mode]
        set_uniform(prog, "wireframe", False)
        prog["hrange"].value = tuple(float(v) for v in self.hf.height_range)
        if self.texture is not None:
            self.texture.use(1)
            prog["tex"].value = 1
        self.blocks.write(tile_blocks(self.hf, view, items, unit_spacing=True))   # positions are metres
        target.use()
        ctx.wireframe = bool(wireframe)
        for i in range(4):
            ctx.enable_direct(GL_CLIP_DISTANCE0 + i)
        query = ctx.query(primitives=True)
        cpu = 0
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
        return {"triangles": int(query.primitives), "triangles_cpu": cpu}

    def release(self) -> None:
        """Free the program, the terrain texture and the tile blocks."""
        self.blocks.release()
        for o in (self.prog, self.texture):
            if o is not None:
                o.release()
