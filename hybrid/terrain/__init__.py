"""Terrain in: the height field (world frame, rows, texel space), file loaders and bundled or synthetic datasets."""
