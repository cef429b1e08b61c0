"""Registration of the tile strategies of raster/ and raycast/ in hybrid.frame.STRATEGIES."""
from __future__ import annotations

from .frame import register_strategy


@register_strategy("raycast")
def _raycast(ctx, hf, shading_source, **options):
    """The max-mipmap ray caster (raycast.RaycastStrategy)."""
    from raycast import RaycastStrategy
    return RaycastStrategy(ctx, hf, shading_source, **options)


# --- raster (issue 4) ------------------------------------------------------------------------------
@register_strategy("raster")
def _raster(ctx, hf, shading_source, **options):
    """Restricted-quadtree tilelets through the geometry shader, stitched and geomorphed."""
    from raster.tilelets import TileletStrategy
    return TileletStrategy(ctx, hf, shading_source, **options)


@register_strategy("fullres")
def _fullres(ctx, hf, shading_source, **options):
    """Full-resolution indexed triangle list per tile."""
    from raster.trianglelist import TriangleListStrategy
    return TriangleListStrategy(ctx, hf, shading_source, **options)


@register_strategy("tin")
def _tin(ctx, hf, shading_source, **options):
    """Decimated TIN per tile (fast-simplification), may crack at tile borders."""
    from raster.tin import TinStrategy
    return TinStrategy(ctx, hf, shading_source, **options)
# --- end raster ------------------------------------------------------------------------------------
