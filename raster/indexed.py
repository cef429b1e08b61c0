"""The raster strategy a user would pick today (``raster``): GPU-selected tilelets as plain indexed triangles.

The same leaves as the paper's path (raster.selection), without a geometry shader: the selection writes every
leaf's 9 vertices and 24 indices (its fan, stitched, with full-resolution cells split SW-NE), and every tile of
the frame is drawn by one multi-draw: each tile's indirect command (count and first index from the selection,
its base instance the tile's item) reads the tile's block as instanced attributes, so the CPU issues one call a
frame however many tiles it draws. Skirts are a small instanced draw of one quad per segment, a call per tile
that has them. Per leaf this is the paper's 9-post template; drawn without instancing because a CPU rasterizer
runs its vertex pipeline once per instance. Wireframe draws polygon edges.
"""

from __future__ import annotations

from hybrid.gl.context import multi_draw_indirect
from hybrid.gl.programs import program

from .frame_items import CMD_SKIRTS, CMD_TEMPLATE, CONTROL_WORDS
from .tileblock import BLOCK_BYTES, BLOCK_DEFINES
from .tilelets import TileletDrawing

# the first five fields of a tile block (raster.tileblock.BLOCK) as per-instance attributes, one block an instance
BLOCK_ATTRIBUTES = f"4f 4f 4f 4f 4i {BLOCK_BYTES - 80}x/i"
BLOCK_NAMES = ("a_origin", "a_spacing", "a_clip_rel", "a_uv", "a_shape")


class IndexedTileletStrategy(TileletDrawing):
    """Restricted-quadtree tilelets selected on the GPU, drawn as indexed triangles (no geometry shader)."""

    writes = "mesh"

    def __init__(self, ctx, hf, **options):
        super().__init__(ctx, hf, **options)
        self.prog = program(
            ctx,
            "raster",
            "template.vert.glsl",
            "tilelet.frag.glsl",
            defines={"MULTI_DRAW": 1, "TILE_BLOCK_ATTRIBUTES": 1, "SURFACE_FROM_VERTEX": 1, **BLOCK_DEFINES},
        )
        self.skirt_prog = program(
            ctx, "raster", "skirt.vert.glsl", "tilelet.frag.glsl", defines={"SKIRT_PROGRAM": 1, **BLOCK_DEFINES}
        )

    def programs(self) -> tuple:
        """The mesh and skirt programs."""
        return (self.prog, self.skirt_prog)

    def arena_arrays(self) -> dict:
        """The arena's leaf vertices with their index buffer, and the frame's skirt segments, one instance each
        (an item's first instance is in its command)."""
        a = self.arena
        return {
            "mesh": self.ctx.vertex_array(
                self.prog,
                [(a.vertices, "4f", "a_vertex"), (self.blocks.buffer, BLOCK_ATTRIBUTES, *BLOCK_NAMES)],
                index_buffer=a.indices,
                index_element_size=4,
            ),
            "skirts": self.ctx.vertex_array(self.skirt_prog, [(self.items.segments, "3f 3f/i", "a_p", "a_q")]),
        }

    def draw_items(self, items: int, wireframe: bool = False) -> None:
        """Every item's leaves as indexed triangles in one multi-draw (each item's count and first index from the
        selection, its block's first fields as instanced attributes of the item its command's base instance
        names)."""
        ctx = self.ctx
        if not items:
            return
        ctx.wireframe = bool(wireframe)
        try:
            multi_draw_indirect(
                self.arena_vaos()["mesh"],
                self.items.control,
                ctx.TRIANGLES,
                20 * self.command(0, CMD_TEMPLATE),
                items,
                4 * CONTROL_WORDS,
            )
        finally:
            ctx.wireframe = False

    def draw_tile_skirts(self, item: int) -> None:
        """The item's skirt quads (one instance a segment)."""
        self.arena_vaos()["skirts"].render_indirect(
            self.items.control, mode=self.ctx.TRIANGLES, count=1, first=self.command(item, CMD_SKIRTS)
        )
