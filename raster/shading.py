"""Shading modes of the raster strategies (the colour code itself is the shared include "shading")."""
from __future__ import annotations

MODES = {"texture": 0, "shaded": 1, "height": 2, "level": 3}
