"""Shading modes of the raster strategies (the colour code itself is the shared include "shading")."""

from __future__ import annotations

from typing import Literal, get_args

RasterMode = Literal["texture", "shaded", "height", "level"]
MODES = {m: i for i, m in enumerate(get_args(RasterMode))}
"""Mode name -> the ``mode`` uniform of the raster shaders."""
