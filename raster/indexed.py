"""The raster strategy a user would pick today (``raster``): GPU-selected tilelets as plain indexed triangles.

The same leaves as the paper's path (raster.selection), without a geometry shader: the selection writes every
leaf's 9 vertices and 24 indices (its fan, stitched, with full-resolution cells split SW-NE), and each tile is
one indexed draw whose count comes from an indirect command; skirts are a small instanced draw of one quad
per segment. Per leaf this is the paper's 9-post template; drawn without instancing because a CPU rasterizer
runs its vertex pipeline once per instance. Wireframe draws polygon edges.
"""
from __future__ import annotations

from hybrid.gl.programs import program

from .frame_items import CMD_SKIRTS, CMD_TEMPLATE
from .tilelets import TileletDrawing


class IndexedTileletStrategy(TileletDrawing):
    """Restricted-quadtree tilelets selected on the GPU, drawn as indexed triangles (no geometry shader)."""

    writes = "mesh"

    def __init__(self, ctx, hf, **options):
        super().__init__(ctx, hf, **options)
        self.prog = program(ctx, "raster", "template.vert.glsl", "tilelet.frag.glsl")
        self.skirt_prog = program(ctx, "raster", "skirt.vert.glsl", "tilelet.frag.glsl", defines={"SKIRT_PROGRAM": 1})

    def programs(self) -> tuple:
        """The mesh and skirt programs."""
        return (self.prog, self.skirt_prog)

    def arena_arrays(self) -> dict:
        """The arena's leaf vertices with their index buffer, and the frame's skirt segments, one instance each
        (an item's first instance is in its command)."""
        a = self.arena
        return {"mesh": self.ctx.vertex_array(self.prog, [(a.vertices, "4f", "a_vertex")], index_buffer=a.indices,
                                              index_element_size=4),
                "skirts": self.ctx.vertex_array(self.skirt_prog, [(self.items.segments, "3f 3f/i", "a_p", "a_q")])}

    def draw_items(self, items: int, wireframe: bool = False) -> None:
        """Each item's leaves as indexed triangles (count and first index from the selection)."""
        ctx, vao, control = self.ctx, self.arena_vaos()["mesh"], self.items.control
        ctx.wireframe = bool(wireframe)
        try:
            for i in range(items):
                self.blocks.bind(i)
                vao.render_indirect(control, mode=ctx.TRIANGLES, count=1, first=self.command(i, CMD_TEMPLATE))
        finally:
            ctx.wireframe = False

    def draw_tile_skirts(self, item: int) -> None:
        """The item's skirt quads (one instance a segment)."""
        self.arena_vaos()["skirts"].render_indirect(self.items.control, mode=self.ctx.TRIANGLES, count=1,
                                                    first=self.command(item, CMD_SKIRTS))
