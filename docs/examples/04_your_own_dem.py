"""Render your own elevation data: write a small GeoTIFF with rasterio, load it, render it.

    python docs/examples/04_your_own_dem.py [OUT_DIR]

Any file GDAL reads works the same way (GeoTIFF/COG, SRTM .hgt, .asc, .vrt, ...): its CRS, transform and
no-data are read, and ground spacing is turned into metres. Writes OUT_DIR/dem.tif and OUT_DIR/dem.png.
"""

import sys
from pathlib import Path

import numpy as np
import rasterio
from rasterio.transform import from_origin

from hybrid import Renderer, View, load_terrain, shared_context

out = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
out.mkdir(parents=True, exist_ok=True)

# A 257 x 257 grid of two hills at 30 m spacing in UTM zone 10N, north-up as GeoTIFFs are stored.
n, spacing = 257, 30.0
y, x = np.mgrid[0:n, 0:n] / (n - 1)
heights = (
    900 * np.exp(-((x - 0.35) ** 2 + (y - 0.4) ** 2) / 0.02)
    + 600 * np.exp(-((x - 0.7) ** 2 + (y - 0.65) ** 2) / 0.03)
    + 50
).astype(np.float32)
with rasterio.open(
    out / "dem.tif",
    "w",
    driver="GTiff",
    width=n,
    height=n,
    count=1,
    dtype="float32",
    crs="EPSG:32610",
    transform=from_origin(550000, 5200000, spacing, spacing),
) as dst:
    dst.write(heights, 1)

hf = load_terrain(out / "dem.tif")  # rows flipped to south-up, spacing in metres
w, d = hf.extent
ox, oy, oz = hf.origin
print(f"loaded {hf.heights.shape[1]} x {hf.heights.shape[0]} samples, extent {w:.0f} x {d:.0f} m")

# Look at the terrain from its south-west corner, 1.5 km above its highest point.
top = oz + float(hf.heights.max())
view = View(
    eye=(ox - 0.3 * w, oy - 0.3 * d, top + 1500.0),
    target=(ox + 0.5 * w, oy + 0.5 * d, oz + 300.0),
    width=320,
    height=180,
)
with Renderer(shared_context(), hf, "raycast", tile_size=64) as renderer:
    frame = renderer.render(view, tau=2 / 3)
frame.save(out / "dem.png")
print(f"wrote {out / 'dem.tif'} and {out / 'dem.png'} (terrain on {100 * frame.mask.mean():.0f} % of pixels)")
