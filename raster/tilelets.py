"""The tilelet strategy: restricted-quadtree tilelets expanded by the geometry shader (paper §2-3).

Per tile the GPU holds the tile's heights in an R32F texture and a point buffer with room for every
possible leaf ((n/2)² points of 36 bytes: south-west post, level, dropped-edge bits, five morph factors).
Per frame the CPU computes each tile's leaf set (raster.restriction.restrict_frame: error-driven split at
tolerance tau * distance / K metres, restricted inside and across tiles, morph factors) and writes one point
per leaf. The vertex shader fetches the 3x3 post heights, morphs the vanishing posts and, for tiles that
cross the frustum, culls the tilelet by its box; the geometry shader emits the fan, dropping midpoints on
edges whose neighbour is coarser. Everything is eye-relative float32; drawing is clipped to tile.clip.
"""
from __future__ import annotations

import time

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import gl_bytes
from hybrid.gl.programs import program, set_uniform
from hybrid.gl.shading import resolve_mode
from hybrid.gl.textures import terrain_texture

from .culling import cull_tilelets
from .quadtree import DEFAULT_BETA, error_pyramid, estimate_triangles, split_errors
from .restriction import TileLod, restrict_frame
from .shading import MODES

DEFAULT_TAU = 2.0 / 3.0
POINT_FORMAT = "4i 4f 1f"
POINT_BYTES = 36
GL_CLIP_DISTANCE0 = 0x3000


def point_records(tset, stitching: bool = True) -> np.ndarray:
    """The tilelet points of a TileletSet as the structured array the VBO holds (36 bytes a point)."""
    lv = tset.leaves
    rec = np.zeros(len(lv), dtype=[("node", "<i4", 4), ("morph", "<f4", 4), ("morph_c", "<f4")])
    rec["node"][:, 0] = lv.j0
    rec["node"][:, 1] = lv.i0
    rec["node"][:, 2] = lv.level
    rec["node"][:, 3] = tset.coarser if stitching else 0
    rec["morph"] = tset.morph[:, :4]
    rec["morph_c"] = tset.morph[:, 4]
    return rec


class TileletTile:
    """GPU objects of one tile (heights texture, point buffer, vertex array) and its CPU error pyramid."""

    def __init__(self, strategy, tile):
        ctx = strategy.ctx
        h = np.ascontiguousarray(tile.heights, dtype=np.float32)
        if h.ndim != 2 or h.shape[0] != h.shape[1] or (h.shape[0] - 1) & (h.shape[0] - 2) or h.shape[0] < 3:
            raise TerrabenchError(f"tile heights must be (n+1)² with n a power of two >= 2, got shape {h.shape}")
        self.n = h.shape[0] - 1
        self.key = tile.key
        self.pyramid = error_pyramid(h, strategy.beta)
        self.heights = ctx.texture((self.n + 1, self.n + 1), 1, h.tobytes(), dtype="f4")
        self.heights.filter = (ctx.NEAREST, ctx.NEAREST)
        self.capacity = (self.n // 2) ** 2
        self.vbo = ctx.buffer(reserve=self.capacity * POINT_BYTES)
        self.vao = ctx.vertex_array(strategy.prog, [(self.vbo, POINT_FORMAT, "a_node", "a_morph", "a_morph_c")])
        self.count = 0

    @property
    def nbytes(self) -> int:
        """Exact GPU bytes of this tile: heights texture (4 bytes a sample) + point buffer capacity."""
        return int((self.n + 1) ** 2 * 4 + self.vbo.size)

    def release(self) -> None:
        """Free the GPU objects."""
        for o in (self.vao, self.vbo, self.heights):
            o.release()


class TileletStrategy:
    """Draws tiles as restricted-quadtree tilelets through the geometry shader, stitched and geomorphed."""

    kind = "raster"
    draw_options = frozenset({"mode", "wireframe", "stitching", "morph", "culling", "leaf_tau", "record_culling",
                              "count_culled", "skirts"})

    def __init__(self, ctx, hf, tau: float = DEFAULT_TAU, beta: float = DEFAULT_BETA):
        if not (np.isfinite(tau) and tau > 0):
            raise TerrabenchError(f"tau must be finite and > 0 pixels, got {tau!r}")
        if not (0.0 < beta < 1.0):
            raise TerrabenchError(f"beta must lie in (0, 1), got {beta!r}")
        self.ctx, self.hf = ctx, hf
        self.tau, self.beta = float(tau), float(beta)
        self.prog = program(ctx, "raster", "tilelet.vert.glsl", "tilelet.frag.glsl", "tilelet.geom.glsl")
        self.texture = terrain_texture(ctx, hf)
        self.flags = None
        self.last_sets = {}
        self.last_culled = {}
        self._cpu_pyramids = {}
        self._sorted_errors = {}

    @property
    def shared_nbytes(self) -> int:
        """GPU bytes shared by all tiles as the driver reports them: colour texture (+ the debug cull buffer)."""
        return gl_bytes(self.texture, self.flags)

    def upload(self, tile) -> TileletTile:
        """Put one tile on the GPU (heights texture + point buffer) and compute its error pyramid."""
        return TileletTile(self, tile)

    def count_triangles(self, tile, selected, view, tau: float | None = None) -> int:
        """Triangles (stitched) this strategy draws for one tile alone at a view, CPU only (no upload needed)."""
        key = _key(tile.key)
        if key not in self._cpu_pyramids:
            self._cpu_pyramids[key] = error_pyramid(np.asarray(tile.heights, dtype=np.float32), self.beta)
        tau = self.tau if tau is None else float(tau)
        tol = tau * float(selected.distance) / view.pixels_per_radian
        return restrict_frame([TileLod(key, self._cpu_pyramids[key], tol)])[key].triangles

    def estimate_triangles(self, tile, selected, view, tau: float | None = None) -> int:
        """Triangles of one tile at a view from its node errors alone (quadtree.estimate_triangles), O(log n)."""
        key = _key(tile.key)
        errs = self._sorted_errors.get(key)
        if errs is None:
            if key not in self._cpu_pyramids:
                self._cpu_pyramids[key] = error_pyramid(np.asarray(tile.heights, dtype=np.float32), self.beta)
            errs = self._sorted_errors[key] = split_errors(self._cpu_pyramids[key])
        tau = self.tau if tau is None else float(tau)
        return estimate_triangles(errs, tau * float(selected.distance) / view.pixels_per_radian)

    def leaf_sets(self, view, items, tau: float | None = None, morph: bool = True) -> dict:
        """Restricted tilelet sets of a frame's items for a view: {key tuple: TileletSet}."""
        tau = self.tau if tau is None else float(tau)
        if not (np.isfinite(tau) and tau > 0):
            raise TerrabenchError(f"leaf_tau must be finite and > 0 pixels, got {tau!r}")
        K = view.pixels_per_radian
        lods = [TileLod(_key(s.key), g.pyramid, tau * float(s.distance) / K) for g, _, s in items]
        return restrict_frame(lods, morph=morph)

    def draw_tiles(self, target, view, items, tau: float | None = None, mode: str | None = None,
                   wireframe: bool = False, stitching: bool = True, morph: bool = True, culling: bool = True,
                   leaf_tau: float | None = None, record_culling: bool = False, count_culled: bool = True,
                   skirts: dict | None = None) -> dict:
        """Draw (gpu_tile, tile, selected) items front to back into target; returns counters.

        Leaves are split to the screen-space bound ``leaf_tau`` when given, else the frame's ``tau`` (px).

        Counters: triangles (GL_PRIMITIVES_GENERATED), triangles_cpu (same count from the leaf sets and the
        CPU mirror of the culling test), tilelets, tilelets_culled, lod_ms (CPU leaf selection time).
        count_culled=False skips the CPU mirror (for timing): tilelets_culled and triangles_cpu are then -1.
        skirts: {tile key: edge bits W=1, E=2, S=4, N=8}: hang vertical skirts from those tile edges down to
        below the tile's lowest point (the hybrid frame asks for them where a raster tile meets a ray-cast
        tile, whose edge may lie lower); skirt triangles are counted in ``triangles`` (the GL query) only.
        """
        mode = resolve_mode(self.hf, mode, MODES)
        ctx, prog = self.ctx, self.prog
        t0 = time.perf_counter()
        sets = self.leaf_sets(view, items, tau if leaf_tau is None else leaf_tau, morph)
        lod_ms = (time.perf_counter() - t0) * 1e3
        self.last_sets = sets
        self.last_culled = {}
        planes = view.frustum_planes_rel()
        prog["view_proj_rel"].write(view.view_proj_rel.T.astype(np.float32).tobytes())
        prog["planes"].write(planes.astype(np.float32).tobytes())
        prog["mode"].value = MODES[mode]
        prog["wireframe"].value = bool(wireframe)
        prog["hrange"].value = tuple(float(v) for v in self.hf.height_range)
        prog["record"].value = bool(record_culling)
        if self.texture is not None:
            self.texture.use(1)
            prog["tex"].value = 1
        prog["heights"].value = 0
        if record_culling:
            need = max((g.capacity for g, _, _ in items), default=1) * 4
            if self.flags is None or self.flags.size < need:
                if self.flags is not None:
                    self.flags.release()
                self.flags = ctx.buffer(reserve=need)
            self.flags.bind_to_storage_buffer(0)
        hf_origin = np.asarray(self.hf.origin, dtype=np.float64)
        extent = np.asarray(self.hf.extent, dtype=np.float64)
        target.use()
        for i in range(4):
            ctx.enable_direct(GL_CLIP_DISTANCE0 + i)
        tri_cpu = tilelets = culled_total = 0
        query = ctx.query(primitives=True)
        try:
            with query:
                for g, tile, sel in items:
                    key = _key(sel.key)
                    tset = sets[key]
                    rec = point_records(tset, stitching)
                    g.vbo.write(rec.tobytes())
                    g.count = len(rec)
                    origin_rel = np.asarray(tile.origin, dtype=np.float64) - view.eye
                    x0, y0, x1, y1 = tile.clip
                    do_cull = bool(culling) and not bool(sel.inside)
                    prog["origin_rel"].value = tuple(origin_rel.astype(np.float32))
                    prog["spacing"].value = float(tile.spacing)
                    prog["cull"].value = do_cull
                    prog["clip_rel"].value = (float(x0 - view.eye[0]), float(y0 - view.eye[1]),
                                              float(x1 - view.eye[0]), float(y1 - view.eye[1]))
                    prog["uv_origin"].value = tuple(((np.asarray(tile.origin[:2]) - hf_origin[:2]) / extent).astype(np.float32))
                    prog["uv_per_cell"].value = tuple((float(tile.spacing) / extent).astype(np.float32))
                    prog["tile_level"].value = int(key[0])
                    set_uniform(prog, "n_cells", int(g.n))
                    set_uniform(prog, "skirt_edges", int((skirts or {}).get(sel.key, 0)))
                    set_uniform(prog, "skirt_bottom", float(tile.zmin - view.eye[2] - 1.0 - 0.01 * tile.spacing))
                    g.heights.use(0)
                    g.vao.render(ctx.POINTS, vertices=g.count)
                    if do_cull and not count_culled and not record_culling:
                        tilelets += len(rec)
                        tri_cpu = culled_total = -1
                        continue
                    if do_cull:
                        c = cull_tilelets(tile.heights, tset.leaves, origin_rel, tile.spacing, planes)
                    else:
                        c = np.zeros(len(rec), bool)
                    self.last_culled[key] = c
                    if record_culling:
                        ctx.finish()
                        gpu = np.frombuffer(self.flags.read(size=len(rec) * 4), dtype=np.uint32).astype(bool)
                        self.last_culled[key] = (c, gpu)
                    drops = np.unpackbits(rec["node"][:, 3].astype(np.uint8)[:, None], axis=1).sum(axis=1)
                    tilelets += len(rec)
                    if tri_cpu >= 0:
                        tri_cpu += int(np.sum((8 - drops)[~c]))
                        culled_total += int(c.sum())
        finally:
            for i in range(4):
                ctx.disable_direct(GL_CLIP_DISTANCE0 + i)
        triangles = int(query.primitives)
        query.release() if hasattr(query, "release") else None
        return {"triangles": triangles, "triangles_cpu": tri_cpu, "tilelets": tilelets,
                "tilelets_culled": culled_total, "lod_ms": lod_ms}

    def release(self) -> None:
        """Free the program, the terrain texture and the debug buffer."""
        for o in (self.prog, self.texture, self.flags):
            if o is not None:
                o.release()


def _key(k) -> tuple:
    """(level, tx, ty) of a tile key object or tuple."""
    if hasattr(k, "level"):
        return (int(k.level), int(k.tx), int(k.ty))
    return tuple(int(v) for v in k)
