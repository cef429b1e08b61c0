"""The terrain's colour texture on the GPU, shared by the reference and every strategy."""
from __future__ import annotations

import numpy as np


def terrain_texture(ctx, hf, anisotropy: float = 1.0):
    """The cell-centred RGB8 colour texture of hf (mipmapped, clamped), or None when hf has none; anisotropic
    filtering is done in the shaders (aniso_texture in shading.glsl), so the texture object's is 1."""
    if getattr(hf, "texture", None) is None:
        return None
    t = np.ascontiguousarray(hf.texture)
    tex = ctx.texture((t.shape[1], t.shape[0]), 3, t.tobytes())
    tex.build_mipmaps()
    tex.anisotropy = float(anisotropy)
    tex.repeat_x = tex.repeat_y = False
    return tex
