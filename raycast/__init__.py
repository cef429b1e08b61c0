"""Ray-cast strategy: per-tile GPU ray casting over a maximum mipmap (Dick et al.)."""
from .caster import GpuTile, RaycastStrategy
from .maxmip import maxmip_levels, maxmip_nbytes
from .options import CastOptions, MODES, RECONSTRUCTIONS, TRAVERSALS

__all__ = ["RaycastStrategy", "GpuTile", "CastOptions", "maxmip_levels", "maxmip_nbytes", "MODES",
           "RECONSTRUCTIONS", "TRAVERSALS"]
