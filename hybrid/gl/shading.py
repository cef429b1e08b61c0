"""Choosing a shading mode: every method shades with the shared colour conventions (shading.glsl)."""

from __future__ import annotations

from hybrid.errors import TerrabenchError

TEXTURE_MODES = ("texture", "texture_plain")


def resolve_mode(hf, mode: str | None, modes) -> str:
    """The mode to use among ``modes``: 'texture' when hf has a texture, else 'shaded', unless ``mode`` is given."""
    if mode is None:
        return "texture" if getattr(hf, "texture", None) is not None else "shaded"
    if mode not in modes:
        raise TerrabenchError(f"unknown shading mode {mode!r}; choose one of {', '.join(modes)}")
    if mode in TEXTURE_MODES and getattr(hf, "texture", None) is None:
        raise TerrabenchError(
            f"terrain {getattr(hf, 'name', '?')!r} has no texture; mode {mode!r} needs one "
            f"(use {', '.join(m for m in modes if m not in TEXTURE_MODES)})"
        )
    return mode
