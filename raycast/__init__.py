"""Ray-cast strategy: per-tile GPU ray casting over a maximum mipmap (Dick et al.).

It satisfies ``hybrid.contract.TileStrategy``, imports ``hybrid``'s lower layers and never ``raster``, the cost
model or the renderer.
"""

from .caster import RaycastStrategy
from .gpu_tile import GpuTile
from .maxmip import bytes_per_sample, maxmip_levels, maxmip_nbytes
from .options import MODES, RECONSTRUCTIONS, TRAVERSALS, CastOptions

__all__ = [
    "MODES",
    "RECONSTRUCTIONS",
    "TRAVERSALS",
    "CastOptions",
    "GpuTile",
    "RaycastStrategy",
    "bytes_per_sample",
    "maxmip_levels",
    "maxmip_nbytes",
]
