"""terrabench's library: terrain, views, the tile tree, the per-tile cost model and the shared frame.

Coordinate conventions are stated once in hybrid.heightfield (world axes, rows, texel space) and
hybrid.view (camera, reversed-Z depth, image rows).
"""
from .errors import TerrabenchError, TerrainLoadError, GLContextError
from .heightfield import HeightField
from .view import View, default_view
from .pyramid import Tile, TileKey, TilePyramid
from .tiletree import SelectedTile, select_tiles, DEFAULT_TAU
from .flight import Flight, preset
from .datasets import get_dataset, puget

__all__ = ["TerrabenchError", "TerrainLoadError", "GLContextError", "HeightField", "View", "default_view",
           "Tile", "TileKey", "TilePyramid", "SelectedTile", "select_tiles", "DEFAULT_TAU", "Flight", "preset",
           "get_dataset", "puget"]
