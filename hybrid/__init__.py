"""terrabench's library: terrain in, cameras and flights, the tile pyramid and tree, the GL context, the
per-tile cost model and the renderer that draws every choice into one colour + depth buffer.

Layers, lowest first (each imports only from those below it; ``tests/test_layering.py`` enforces it):
``errors`` -> ``terrain`` -> ``camera`` -> ``tiles`` -> ``gl`` -> ``contract`` -> the strategies (packages
``raster``, ``raycast``) -> ``strategies`` (registry) -> ``cost`` -> ``reference``, ``residency``,
``renderer`` -> ``calibrate``. The names of the lower layers are imported here; those above the strategies
load on first use, so ``raster`` and ``raycast`` can import ``hybrid``'s lower layers without a cycle.
"""

from importlib import import_module

from hybrid.camera.flight import Flight, get_flight, preset
from hybrid.camera.view import View, default_view
from hybrid.errors import GLContextError, TerrabenchError, TerrainLoadError
from hybrid.terrain.datasets import get_dataset, puget
from hybrid.terrain.heightfield import HeightField
from hybrid.terrain.loaders import load_terrain
from hybrid.tiles.pyramid import Tile, TileKey, TilePyramid
from hybrid.tiles.tiletree import DEFAULT_TAU, SelectedTile, select_tiles

_UPPER = {
    "FrameStats": "hybrid.contract",
    "TileStrategy": "hybrid.contract",
    "GpuTile": "hybrid.contract",
    "TileItem": "hybrid.contract",
    "Policy": "hybrid.contract",
    "Method": "hybrid.contract",
    "shared_context": "hybrid.gl.context",
    "gl_info": "hybrid.gl.context",
    "RenderResult": "hybrid.gl.target",
    "STRATEGIES": "hybrid.strategies",
    "make_strategy": "hybrid.strategies",
    "register_strategy": "hybrid.strategies",
    "register_policy": "hybrid.strategies",
    "CostModel": "hybrid.cost.model",
    "load_cost_model": "hybrid.cost.model",
    "TilePlan": "hybrid.cost.planner",
    "plan_frame": "hybrid.cost.planner",
    "TileFeatures": "hybrid.cost.features",
    "ReferenceRenderer": "hybrid.reference",
    "Renderer": "hybrid.renderer",
    "make_renderer": "hybrid.renderer",
    "ResidencyCache": "hybrid.residency",
}


def __getattr__(name: str):
    """The public names of the layers above the strategies, imported on first use."""
    if name in _UPPER:
        return getattr(import_module(_UPPER[name]), name)
    raise AttributeError(f"module 'hybrid' has no attribute {name!r}")


__all__ = [
    "TerrabenchError",
    "TerrainLoadError",
    "GLContextError",
    "HeightField",
    "load_terrain",
    "get_dataset",
    "puget",
    "View",
    "default_view",
    "Flight",
    "preset",
    "get_flight",
    "Tile",
    "TileKey",
    "TilePyramid",
    "SelectedTile",
    "select_tiles",
    "DEFAULT_TAU",
    *_UPPER,
]
