"""GPU meshes of the baselines: a vertex buffer of tile-local float32 positions and a uint32 index buffer.

Bytes per triangle of an indexed list: 12 bytes of indices (the paper's 96 bits) plus the vertex buffer
(12 bytes a vertex) shared between triangles.
"""
from __future__ import annotations

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import gl_bytes
from hybrid.gl.programs import program
from hybrid.gl.shading import resolve_mode
from hybrid.gl.textures import terrain_texture

from .shading import MODES

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
        self.prog = program(ctx, "raster", "mesh.vert.glsl", "tilelet.frag.glsl")
        self.texture = terrain_texture(ctx, hf)

    @property
    def shared_nbytes(self) -> int:
        """GPU bytes shared by all tiles as the driver reports them (the colour texture with mipmaps)."""
        return gl_bytes(self.texture)

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
        if "wireframe" in prog:
            prog["wireframe"].value = False
        prog["hrange"].value = tuple(float(v) for v in self.hf.height_range)
        if self.texture is not None:
            self.texture.use(1)
            prog["tex"].value = 1
        hf_origin = np.asarray(self.hf.origin, dtype=np.float64)
        extent = np.asarray(self.hf.extent, dtype=np.float64)
        target.use()
        ctx.wireframe = bool(wireframe)
        for i in range(4):
            ctx.enable_direct(GL_CLIP_DISTANCE0 + i)
        query = ctx.query(primitives=True)
        cpu = 0
        try:
            with query:
                for g, tile, sel in items:
                    origin_rel = np.asarray(tile.origin, dtype=np.float64) - view.eye
                    x0, y0, x1, y1 = tile.clip
                    prog["origin_rel"].value = tuple(origin_rel.astype(np.float32))
                    prog["clip_rel"].value = (float(x0 - view.eye[0]), float(y0 - view.eye[1]),
                                              float(x1 - view.eye[0]), float(y1 - view.eye[1]))
                    prog["uv_origin"].value = tuple(((np.asarray(tile.origin[:2]) - hf_origin[:2]) / extent).astype(np.float32))
                    prog["spacing"].value = 1.0          # mesh positions are in metres: one "cell" a metre
                    prog["uv_per_cell"].value = tuple((1.0 / extent).astype(np.float32))
                    prog["tile_level"].value = int(sel.key.level)
                    g.vao.render(ctx.TRIANGLES)
                    cpu += g.triangles
        finally:
            ctx.wireframe = False
            for i in range(4):
                ctx.disable_direct(GL_CLIP_DISTANCE0 + i)
        return {"triangles": int(query.primitives), "triangles_cpu": cpu}

    def release(self) -> None:
        """Free the program and the terrain texture."""
        for o in (self.prog, self.texture):
            if o is not None:
                o.release()
