"""The paper's raster strategy (``raster_gs``): GPU-selected tilelets expanded by the geometry shader
(Bhattacharjee et al.).

Leaves come from the GPU selection (raster.selection): one point per leaf, drawn with an indirect command,
expanded by the geometry shader into its 8-triangle fan (stitched where the neighbour is coarser, four
SW-NE cells at full resolution) with skirts on edges that face ray-cast tiles. Nothing about the mesh is
computed on the CPU per frame; the CPU sets uniforms and issues two dispatches a frame and one draw per tile.
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from hybrid.contract import DEFAULT_FULL_RES
from hybrid.gl.edges import TerrainEdges
from hybrid.gl.programs import program
from hybrid.gl.shading import resolve_mode

from .edit import stale_tiles
from .frame_items import BASE_WORD, CMD_POINTS
from .options import TileletOptions
from .selection import LEAF_FORMAT, LEAN_LEAF_FORMAT, SelectedTileletTile, TileletSelection, full_res_defines
from .shading import MODES
from .tileblock import BLOCK_DEFINES

GL_CLIP_DISTANCE0 = 0x3000


def read_leaves(strategy, g: SelectedTileletTile) -> dict:
    """The leaves the last selection of a tilelet strategy drew for its tile g (its first drawing in the frame;
    for tests): level and triangles (non-degenerate) of each, with j0, i0, dropped-edge bits and post heights
    (and with lean full-resolution leaves the SE and NW cells' turns) where it wrote leaf records."""
    words = strategy.control_words(strategy.item_of[id(g)])
    count, base = int(words[5 * CMD_POINTS]), int(words[BASE_WORD])
    a = strategy.arena
    record_bytes, vertex_bytes, index_bytes = a.leaf_bytes

    def read(buf, nbytes: int, dtype) -> np.ndarray:
        if not count:
            return np.zeros(0, dtype)
        return np.frombuffer(buf.read(size=count * nbytes, offset=base * nbytes), dtype)

    if g.writes == "mesh":
        v, i = read(a.vertices, vertex_bytes, np.float32), read(a.indices, index_bytes, np.uint32)
        tri = i.reshape(count, index_bytes // 12, 3)
        solid = (tri[..., 0] != tri[..., 1]) & (tri[..., 1] != tri[..., 2]) & (tri[..., 0] != tri[..., 2])
        return {
            "level": v.reshape(count, vertex_bytes // 16, 4)[:, 0, 3].astype(np.int32),
            "triangles": solid.sum(axis=1),
        }
    raw = read(a.records, record_bytes, np.uint32).reshape(count, record_bytes // 4)
    drop = raw[:, 3].astype(np.int32)
    out = {
        "j0": raw[:, 0].astype(np.int32),
        "i0": raw[:, 1].astype(np.int32),
        "level": raw[:, 2].astype(np.int32),
        "drop": drop,
        "heights": raw[:, 4:13].view(np.float32).copy(),
        "triangles": 8 - np.unpackbits(drop.astype(np.uint8)[:, None], axis=1).sum(axis=1),
    }
    if raw.shape[1] > 13:
        out["turns"] = raw[:, 13:15].view(np.float32).copy()
        out["triangles"] = out["triangles"] + 2 * (out["turns"] > 0).sum(axis=1)
    return out


class TileletDrawing(TileletSelection):
    """Uniforms and state shared by both tilelet draws; subclasses issue the draw of one tile."""

    options_type = TileletOptions
    draw_options = frozenset({f.name for f in fields(TileletOptions)} | {"skirts"})  # skirts: the renderer's

    def __init__(self, ctx, hf, **options):
        super().__init__(ctx, hf, **options)
        self._skirted: list = []  # items of the last draw_tiles call that hang skirts
        self.edges = TerrainEdges(ctx, hf)  # skirts are not drawn for rays from under the sheet
        self.skirt_prog = None  # the program that draws skirts (subclasses)
        # ((arena, item buffers, tile blocks) versions, vertex arrays over them)
        self._arena_vaos: tuple[tuple[int, int, int] | None, dict] = (None, {})

    def follow_edit(self, change, resident, tile) -> tuple[int, list]:
        """Follow an edit (``hybrid.contract.EditFollowing``): the resident tiles it changed, to upload again."""
        return stale_tiles(change, resident)

    @property
    def shared_nbytes(self) -> int:
        """GPU bytes shared by all tiles, as the driver reports them: colour texture, frame counters, edges."""
        return super().shared_nbytes + self.edges.nbytes

    def programs(self) -> tuple:
        """Every program whose uniforms follow the frame (subclasses)."""
        raise NotImplementedError

    def draw_items(self, items: int, wireframe: bool = False) -> None:
        """Issue the indirect draws of items 0 .. items - 1 from the frame's control buffer, each reading its own
        tile block (subclasses)."""
        raise NotImplementedError

    def arena_arrays(self) -> dict:
        """Vertex arrays over the frame's shared buffers as they are now: the arena's, and the item buffers'
        (subclasses)."""
        raise NotImplementedError

    def arena_vaos(self) -> dict:
        """The vertex arrays over the frame's shared buffers, made again when the arena's, the item buffers' or the
        tile blocks' were replaced."""
        version, vaos = self._arena_vaos
        now = (self.arena.version, self.items.version, self.blocks.version)
        if version != now:
            for v in vaos.values():
                v.release()
            vaos = self.arena_arrays()
            self._arena_vaos = (now, vaos)
        return vaos

    def draw_tile_skirts(self, item: int) -> None:
        """Issue item ``item``'s skirt draw from the frame's control buffer (subclasses)."""
        raise NotImplementedError

    def draw_skirts(self, target, view) -> None:
        """Draw the skirts of the last draw_tiles call (after the ray-cast tiles, so that the ray caster's
        pre-pass never sees a skirt inside a ray-cast tile's box): they show only where nothing is nearer."""
        items = self._skirted
        if not items:
            return
        ctx = self.ctx
        self.edges.bind(self.skirt_prog, self.hf, view, 6)
        target.use()
        for i in range(4):
            ctx.enable_direct(GL_CLIP_DISTANCE0 + i)
        try:
            for i in items:
                self.blocks.bind(i)
                self.draw_tile_skirts(i)
        finally:
            for i in range(4):
                ctx.disable_direct(GL_CLIP_DISTANCE0 + i)

    def draw_tiles(
        self,
        target,
        view,
        items,
        tau: float | None = None,
        mode: str | None = None,
        wireframe: bool = False,
        morph: bool = True,
        stitching: bool = True,
        lean: bool = True,
        culling: bool = True,
        leaf_tau: float | None = None,
        skirts: dict | None = None,
        full_res: str = DEFAULT_FULL_RES,
        lod_eye=None,
    ) -> dict:
        """Select and draw (gpu_tile, tile, selected) items into target at tau px (``leaf_tau`` overrides it).

        ``skirts`` {tile key: edge bits} are selected here and drawn by ``draw_skirts``, which the renderer
        calls after the ray-cast tiles. ``lean`` drops the edge midpoints that neither a finer neighbour nor a near
        split needs (off: a leaf drops only those toward coarser neighbours); ``full_res`` is the full-resolution
        leaves' rule (hybrid.contract.FULL_RES: "exact" keeps their midpoints, "lean" drops them as others);
        ``lod_eye`` (world metres) selects the leaves as seen from there (a held level of detail). Counters:
        triangles (drawn, stitched), tilelets, tilelets_culled, skirt_segments, arena_leaves (leaves the arena
        held), arena_overflow (0: the frame drawn missed no leaf), arena_regrown (1 if the arena grew and the frame
        was drawn again).
        """
        mode = resolve_mode(self.hf, mode, MODES)
        tau = leaf_tau if leaf_tau is not None else tau
        self.use_full_res(full_res)
        self.set_selection("morph", bool(morph))
        self.set_selection("stitch", bool(stitching))
        self.set_selection("lean", bool(lean))
        self.arena.prepare(len(items), view.width * view.height)  # for the recent calls' leaves, with room to grow
        counters = self._select_draw(target, view, items, tau, mode, wireframe, culling, skirts, lod_eye)
        regrown = 0
        if counters["arena_overflow"]:  # some tiles did not fit and drew nothing: grow, draw them
            self.arena.remake(counters["arena_leaves"])
            regrown = 1
            counters = self._select_draw(target, view, items, tau, mode, wireframe, culling, skirts, lod_eye)
            if counters["arena_overflow"]:
                raise RuntimeError(
                    f"leaf arena of {self.arena.capacity} leaves overflowed after growing for "
                    f"{counters['arena_leaves']}"
                )
        self.arena.note(counters["arena_leaves"], len(items))
        counters["arena_regrown"] = regrown
        return counters

    def _select_draw(self, target, view, items, tau, mode, wireframe, culling, skirts, lod_eye) -> dict:
        """One selection and draw of the items (the depth test keeps a repeated draw's pixels as they were)."""
        self.select_leaves(view, items, tau, culling, skirts, lod_eye)
        ctx = self.ctx
        vp = view.view_proj_rel.T.astype(np.float32).tobytes()
        for prog in self.programs():
            prog["view_proj_rel"].write(vp)
            self.uniforms.set(prog, "mode", MODES[mode])
            self.uniforms.set(prog, "wireframe", bool(wireframe))
            self.uniforms.set(prog, "hrange", tuple(float(v) for v in self.hf.height_range))
            self.uniforms.set(prog, "tex", 1)
        if self.texture is not None:
            self.texture.use(1)
        target.use()
        for i in range(4):
            ctx.enable_direct(GL_CLIP_DISTANCE0 + i)
        try:
            self.draw_items(len(items), wireframe)
            self._skirted = [i for i, (_, _, sel) in enumerate(items) if (skirts or {}).get(sel.key, 0)]
        finally:
            for i in range(4):
                ctx.disable_direct(GL_CLIP_DISTANCE0 + i)
        return self.frame_counters()

    def release(self) -> None:
        """Free the programs, the selection shader, the texture and the counters."""
        for prog in self.programs():
            prog.release()
        for v in self._arena_vaos[1].values():
            v.release()
        self.edges.release()
        super().release()


class TileletStrategy(TileletDrawing):
    """Restricted-quadtree tilelets selected on the GPU and expanded by the geometry shader (the paper's path)."""

    def __init__(self, ctx, hf, **options):
        super().__init__(ctx, hf, **options)
        self._programs = {"exact": self._compile("exact")}
        self.prog, self.skirt_prog = self._programs["exact"]

    def _compile(self, full_res: str) -> tuple:
        """The geometry-shader program and its skirt-pass variant for a full-resolution rule's leaf records."""
        progs = tuple(
            program(
                self.ctx,
                "raster",
                "leaf.vert.glsl",
                "tilelet.frag.glsl",
                "tilelet.geom.glsl",
                defines={**full_res_defines(full_res), **BLOCK_DEFINES, **skirt},
            )
            for skirt in ({}, {"SKIRT_PROGRAM": 1})
        )
        progs[0]["skirt_pass"].value = False
        progs[1]["skirt_pass"].value = True
        return progs

    def use_full_res(self, full_res: str) -> None:
        """The selection's and the programs' full-resolution rule (``TileletSelection.use_full_res``)."""
        super().use_full_res(full_res)
        if full_res not in self._programs:
            self._programs[full_res] = self._compile(full_res)
        self.prog, self.skirt_prog = self._programs[full_res]

    def programs(self) -> tuple:
        """The geometry-shader program and its skirt-pass variant."""
        return (self.prog, self.skirt_prog)

    def release(self) -> None:
        """Free every full-resolution rule's programs, then what the drawing holds."""
        for progs in self._programs.values():
            if progs[0] is not self.prog:
                for p in progs:
                    p.release()
        super().release()

    def arena_arrays(self) -> dict:
        """Two vertex arrays of the arena's leaf records as points: for the mesh and for the skirt program."""
        attrs: list[tuple] = [(self.arena.records, LEAF_FORMAT, "a_node", "a_h0", "a_h1", "a_h8")]
        if self.full_res == "lean":
            attrs = [(self.arena.records, LEAN_LEAF_FORMAT, "a_node", "a_h0", "a_h1", "a_h8", "a_turn")]
        return {
            "points": self.ctx.vertex_array(self.prog, attrs),
            "skirt_points": self.ctx.vertex_array(self.skirt_prog, attrs),
        }

    def draw_items(self, items: int, wireframe: bool = False) -> None:
        """Each item's leaves as points through the geometry shader (count and first leaf from the selection)."""
        vao, control = self.arena_vaos()["points"], self.items.control
        for i in range(items):
            self.blocks.bind(i)
            vao.render_indirect(control, mode=self.ctx.POINTS, count=1, first=self.command(i, CMD_POINTS))

    def draw_tile_skirts(self, item: int) -> None:
        """The item's leaves again through the geometry shader's skirt program, emitting only their skirts."""
        self.arena_vaos()["skirt_points"].render_indirect(
            self.items.control, mode=self.ctx.POINTS, count=1, first=self.command(item, CMD_POINTS)
        )
