"""The raster strategy a user would pick today: GPU-selected tilelets drawn as an instanced template.

The same leaves as the paper's path (raster.selection), without a geometry shader: one instance of an
8-triangle template per leaf, positions pulled from the leaf's record in the vertex shader, and the skirts as
a second instanced draw of one quad per segment. Both draws take their counts from indirect commands.
"""
from __future__ import annotations

from hybrid.gl.programs import program

from .selection import CMD_SKIRTS, CMD_TEMPLATE, LEAF_FORMAT, SelectedTileletTile
from .tilelets import TileletDrawing


class InstancedTileletStrategy(TileletDrawing):
    """Restricted-quadtree tilelets selected on the GPU and drawn as an instanced template (no geometry shader)."""

    def __init__(self, ctx, hf, **options):
        super().__init__(ctx, hf, **options)
        self.prog = program(ctx, "raster", "template.vert.glsl", "tilelet.frag.glsl")
        self.skirt_prog = program(ctx, "raster", "skirt.vert.glsl", "tilelet.frag.glsl")

    def programs(self) -> tuple:
        """The template and skirt programs."""
        return (self.prog, self.skirt_prog)

    def tile_arrays(self, g: SelectedTileletTile) -> dict:
        """Per-instance leaf records for the template, per-instance segments for the skirts."""
        fmt = LEAF_FORMAT + "/i"
        return {"template": self.ctx.vertex_array(self.prog, [(g.leaves, fmt, "a_node", "a_h0", "a_h1", "a_h8")]),
                "skirts": self.ctx.vertex_array(self.skirt_prog, [(g.segments, "3f 3f/i", "a_p", "a_q")])}

    def draw_tile(self, g: SelectedTileletTile, tile, view) -> None:
        """The tile's leaves as template instances, then its skirt quads."""
        ctx = self.ctx
        g.vaos["template"].render_indirect(g.commands, mode=ctx.TRIANGLES, count=1, first=CMD_TEMPLATE)
        g.vaos["skirts"].render_indirect(g.commands, mode=ctx.TRIANGLES, count=1, first=CMD_SKIRTS)
