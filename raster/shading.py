"""Shading modes shared by the raster strategies (the colour code itself is the shared shading source)."""
from __future__ import annotations

MODES = {"texture": 0, "shaded": 1, "height": 2, "level": 3}


def resolve_mode(hf, mode) -> str:
    """Mode name to use: 'texture' when the terrain has one, else 'shaded', unless ``mode`` is given."""
    if mode is None:
        return "texture" if getattr(hf, "texture", None) is not None else "shaded"
    if mode not in MODES:
        raise ValueError(f"unknown shading mode {mode!r}; choose one of {', '.join(MODES)}")
    if mode == "texture" and getattr(hf, "texture", None) is None:
        raise ValueError(f"terrain {getattr(hf, 'name', '?')!r} has no texture; use mode 'shaded', 'height' or 'level'")
    return mode


def load_glsl(name: str, shading_source: str) -> str:
    """Text of a GLSL file of this package with ``//#include shading.glsl`` replaced by shading_source."""
    from importlib import resources
    text = (resources.files("raster") / name).read_text()
    return text.replace("//#include shading.glsl", shading_source)


def terrain_texture(ctx, hf):
    """The terrain's colour texture (mipmapped, clamped) on the GPU, or None when hf has none."""
    import numpy as np
    if getattr(hf, "texture", None) is None:
        return None
    t = ctx.texture((hf.cols - 1, hf.rows - 1), 3, np.ascontiguousarray(hf.texture).tobytes())
    t.build_mipmaps()
    t.anisotropy = 16.0
    t.repeat_x = t.repeat_y = False
    return t


def texture_nbytes(hf) -> int:
    """Bytes of the terrain texture with its full mip chain as uploaded (RGB8, 3 bytes a texel)."""
    if getattr(hf, "texture", None) is None:
        return 0
    w, h = hf.cols - 1, hf.rows - 1
    total = 0
    while True:
        total += w * h * 3
        if w == 1 and h == 1:
            return total
        w, h = max(1, w // 2), max(1, h // 2)
