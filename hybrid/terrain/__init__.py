"""Terrain in: the height field (world frame, rows, texel space), file loaders (GDAL formats through rasterio,
georeferenced with pyproj; no-data voids filled), terrain sources and bundled or synthetic datasets."""
