"""The terrain's colour texture on the GPU, shared by the reference and every strategy."""

from __future__ import annotations

import numpy as np

from hybrid.gl.context import max_texture_size


def fit_texture(t: np.ndarray, limit: int) -> np.ndarray:
    """An RGB8 image (rows, cols, 3) resampled by area to fit ``limit`` texels a side, keeping its aspect; the
    image itself when it fits. Its texels still span the whole terrain, so texture coordinates are unchanged."""
    rows, cols = t.shape[:2]
    if max(rows, cols) <= limit:
        return t
    from skimage.transform import resize

    f = limit / max(rows, cols)
    shape = (max(1, min(limit, round(rows * f))), max(1, min(limit, round(cols * f))), t.shape[2])
    out = resize(t, shape, order=1, anti_aliasing=True, preserve_range=True)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def terrain_texture(ctx, hf, anisotropy: float = 1.0):
    """The cell-centred RGB8 colour texture of hf (mipmapped, clamped), or None when hf has none; one wider than
    the context's texture limit is resampled to fit it (``fit_texture``); anisotropic filtering is done in the
    shaders (aniso_texture in shading.glsl), so the texture object's is 1."""
    if getattr(hf, "texture", None) is None:
        return None
    t = np.ascontiguousarray(fit_texture(np.asarray(hf.texture), max_texture_size(ctx)))
    tex = ctx.texture((t.shape[1], t.shape[0]), 3, t.tobytes())
    tex.build_mipmaps()
    tex.anisotropy = float(anisotropy)
    tex.repeat_x = tex.repeat_y = False
    return tex
