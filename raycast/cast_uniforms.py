"""The ray-cast program's frame uniforms: the view's, the terrain's and its textures' units, and the shadow grid's.

Texture units: 0 and 1 a tile's heights and max mipmap (bound per tile), 2 the colour texture, 3 and 5 the
shadow grid's heights and max mipmap, 4 the tile IDs, 6 the terrain's edges, 8 the earlier passes' depth.
"""

from __future__ import annotations

import numpy as np

from hybrid.gl.programs import set_uniform, write_uniform

from .maxmip import level_count
from .options import default_max_steps


def view_uniforms(prog, prepass_prog, view, hf, texture, edges, heat_max: float) -> None:
    """The view's, the terrain's and the textures' uniforms of the cast program (and the pre-pass's view)."""
    W, H = int(view.width), int(view.height)
    vp = np.asarray(view.view_proj_rel, dtype=np.float64)
    write_uniform(prog, "view_proj_rel", vp.T.astype(np.float32).tobytes())
    prepass_prog["view_proj_rel"].write(vp.T.astype(np.float32).tobytes())
    write_uniform(prog, "cam_to_world", np.asarray(view.rotation(), np.float64).astype(np.float32).tobytes())
    t = float(view.tan_half_fov)
    set_uniform(prog, "ndc_scale", (t * W / H, t))
    set_uniform(prog, "viewport", (float(W), float(H)))
    set_uniform(prog, "near_plane", float(view.near))
    set_uniform(prog, "far_plane", float(view.far))
    lo, hi = hf.height_range
    set_uniform(prog, "hrange", (lo, hi))
    set_uniform(prog, "heat_max", float(heat_max))
    if texture is not None:
        texture.use(2)
        set_uniform(prog, "tex", 2)
    set_uniform(prog, "hmap", 0)
    edges.bind(prog, hf, view, 6)


def shadow_uniforms(prog, grid, hf, max_steps: int | None) -> None:
    """Bind the whole terrain's shadow grid (raycast.gpu_tile.ShadowGrid) and set its uniforms."""
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
    set_uniform(prog, "g_max_steps", max_steps or default_max_steps(grid.n))
