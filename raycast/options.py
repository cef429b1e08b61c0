"""Options of the ray caster (reconstruction, traversal, pre-pass, LOD, shading mode, shadows, caps), checked."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal, get_args

from hybrid.contract import DrawOptions, check_flags
from hybrid.errors import TerrabenchError

Reconstruction = Literal["planes", "linear", "triangles", "bilinear"]
Traversal = Literal["maxmip", "naive"]
CastMode = Literal["texture", "texture_plain", "shaded", "height", "normal", "depth", "level", "steps"]
RECONSTRUCTIONS: tuple[str, ...] = get_args(Reconstruction)
TRAVERSALS: tuple[str, ...] = get_args(Traversal)
MODES: tuple[str, ...] = get_args(CastMode)
HeightFormat = Literal["uint16", "float32"]
HEIGHT_FORMATS: tuple[str, ...] = get_args(HeightFormat)


@dataclass(frozen=True)
class CastOptions(DrawOptions):
    """How tiles are ray cast and shaded.

    reconstruction: surface inside a cell ('planes' = piecewise constant box of the cell's max-mip height
      (Dick), 'linear' = Qu's linear approximation planes, 'triangles' = two triangles split SW-NE (Qu 3.2,
      the reference surface), 'bilinear' = bilinear patch, intersected analytically).
    traversal: 'maxmip' (hierarchical, Dick 3.2) or 'naive' (every level-0 texel along the ray).
    prepass: tile-ID pre-pass so only pixels still empty cast a ray (Dick 3.4); None: the default
      (``prepass_default``: off, since it did not pay on any device measured).
    occluders: what the target's depth holds when the pass starts (an earlier pass of the frame: the raster
      tiles of a mixed frame) bounds every ray, which stops where it would pass behind it; None: the renderer
      turns it on where raster tiles lie in front of ray-cast ones.
    lod: None, or tau in pixels: stop descending at the level whose texel projects to <= tau pixels.
    mode: shading mode (None = 'texture' when the terrain has one, else 'shaded').
    shadows: cast a shadow ray toward LIGHT_DIR from every hit (whole terrain, primary ray's level).
    max_steps: step cap per ray (None = 8 N + 64 for a grid of N cells); capped rays are misses.
    stats: count rays, hits, steps and capped rays per tile, exactly (summed per subgroup, then atomics).
    heat_max: steps mapped to the top of the 'steps' heat map.
    heights: texel format of a tile's heights and max mipmap: 'uint16' (16-bit codes, hybrid.tiles.quantize;
      2.67 bytes a sample) or 'float32' (metres as they are, 5.33 bytes a sample: the baseline that measures what
      the codes cost). Fixed when the strategy is made (``upload_fields``); 'float32' tiles cast no shadows.
    """

    upload_fields: ClassVar[tuple[str, ...]] = ("heights",)

    reconstruction: Reconstruction = "triangles"
    traversal: Traversal = "maxmip"
    prepass: bool | None = None
    occluders: bool | None = None
    lod: float | None = None
    mode: CastMode | None = None
    shadows: bool = False
    max_steps: int | None = None
    stats: bool = True
    heat_max: float = 64.0
    heights: HeightFormat = "uint16"

    def __post_init__(self):
        if self.reconstruction not in RECONSTRUCTIONS:
            raise TerrabenchError(
                f"reconstruction must be one of {', '.join(RECONSTRUCTIONS)}, got {self.reconstruction!r}"
            )
        if self.traversal not in TRAVERSALS:
            raise TerrabenchError(f"traversal must be one of {', '.join(TRAVERSALS)}, got {self.traversal!r}")
        if self.mode is not None and self.mode not in MODES:
            raise TerrabenchError(f"mode must be one of {', '.join(MODES)} (or None), got {self.mode!r}")
        if self.prepass is not None and not isinstance(self.prepass, bool):
            raise TerrabenchError(f"prepass must be True, False or None (the device's default), got {self.prepass!r}")
        check_flags(self, ("shadows", "stats"))
        if self.heights not in HEIGHT_FORMATS:
            raise TerrabenchError(f"heights must be one of {', '.join(HEIGHT_FORMATS)}, got {self.heights!r}")
        if self.heights == "float32" and self.shadows:
            raise TerrabenchError("shadows need heights='uint16' (the shadow rays' grid is 16-bit codes)")
        if self.occluders is not None and not isinstance(self.occluders, bool):
            raise TerrabenchError(f"occluders must be True, False or None (the renderer's), got {self.occluders!r}")
        if self.lod is not None:
            if isinstance(self.lod, bool) or not isinstance(self.lod, (int, float)) or not (0 < float(self.lod) < 1e6):
                raise TerrabenchError(f"lod must be None or a tau in pixels in (0, 1e6), got {self.lod!r}")
            if self.traversal == "naive":
                raise TerrabenchError("lod needs traversal='maxmip' (naive stepping stays at level 0)")
        if self.max_steps is not None and (
            isinstance(self.max_steps, bool)
            or not isinstance(self.max_steps, int)
            or not (1 <= self.max_steps <= 1_000_000)
        ):
            raise TerrabenchError(f"max_steps must be None or an integer in [1, 1000000], got {self.max_steps!r}")
        if isinstance(self.heat_max, bool) or not isinstance(self.heat_max, (int, float)) or not self.heat_max > 0:
            raise TerrabenchError(f"heat_max must be a number of steps > 0, got {self.heat_max!r}")


def default_max_steps(n: int) -> int:
    """Default step cap for a grid of n cells a side: 8 n + 64 (naive stepping needs at most 2 n + 1)."""
    return 8 * int(n) + 64


def prepass_default() -> bool:
    """Whether the tile-ID pre-pass is on by default: it is not, having paid on no device measured.

    The pre-pass saves at most the rays it culls, and on Puget's flights those are few: tiles are cast front to
    back and a ray already stops where a nearer tile's hit lies, so the pre-pass culls 3.7 % of the flyover's
    rays, 4.9 % of the dolly's and 6.2 % of the grazing flight's, while each tile pays an extra box pass and two
    framebuffer switches. Measured with the same images: llvmpipe 0.92x, 0.95x and 1.02x the speed without it
    (a tiled CPU rasterizer must also finish each tile's pre-pass before its cast); the NVIDIA H200 0.93x on
    the flyover. ``prepass=True`` still turns it on."""
    return False
