"""Registration of the tile strategies of raster/ and raycast/ in hybrid.frame.STRATEGIES."""
from __future__ import annotations

from .frame import register_strategy


@register_strategy("raycast")
def _raycast(ctx, hf, shading_source, **options):
    """The max-mipmap ray caster (raycast.RaycastStrategy)."""
    from raycast import RaycastStrategy
    return RaycastStrategy(ctx, hf, shading_source, **options)
