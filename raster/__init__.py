"""Raster strategy: restricted-quadtree tilelet meshes through the geometry shader, and mesh baselines."""
