"""Rasterized terrain meshes: restricted-quadtree tilelets expanded by a geometry shader (Bhattacharjee
et al. 2008, §2-3) with stitching and geomorphing, plus full-resolution and decimated-TIN baselines.

This package takes duck-typed tiles, views and selected tiles (see hybrid.frame) and never imports hybrid.
"""
