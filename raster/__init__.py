"""Rasterized terrain meshes: restricted-quadtree tilelets expanded by a geometry shader (Bhattacharjee
et al. 2008, §2-3) with stitching and geomorphing, plus full-resolution and decimated-TIN baselines.

Strategies here satisfy ``hybrid.contract.TileStrategy``; they import ``hybrid``'s lower layers (terrain,
camera, tiles, gl) and never ``raycast``, the cost model or the renderer.
"""
