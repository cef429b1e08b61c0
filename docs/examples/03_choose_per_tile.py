"""Let the cost model choose raster or ray casting per tile, then draw the mix with the hybrid.

    python docs/examples/03_choose_per_tile.py [OUT_DIR]

Planning needs no GL context; drawing does. Writes OUT_DIR/plans.csv (one row per tile: features, predicted
ms per strategy, choice), OUT_DIR/hybrid.png and OUT_DIR/hybrid.strategy.png (blue raster, orange ray cast).
"""

import csv
import sys
from pathlib import Path

import numpy as np
from PIL import Image

from hybrid import Renderer, TilePyramid, gl_info, load_cost_model, plan_frame, preset, puget, shared_context

out = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
out.mkdir(parents=True, exist_ok=True)

ctx = shared_context()
hf = puget(size=513)  # a 513² window around Mount Rainier
pyramid = TilePyramid(hf, tile_size=64)  # tiles, bounding boxes, geometric errors (no GL)
view = preset("flyover", hf, frames=8, width=320, height=180).view(3)
model = load_cost_model(gl_info(ctx).renderer)  # this device's calibrated model, else the fallback

plans = plan_frame(pyramid, view, model, policy="hybrid", tau=2 / 3)
with open(out / "plans.csv", "w", newline="") as f:
    writer = csv.writer(f)
    writer.writerow(["tile", "pixels", "triangles", "raster_ms", "raycast_ms", "choice"])
    for p in plans:
        writer.writerow(
            [
                str(p.key),
                round(p.features.pixels),
                round(p.features.triangles),
                round(p.predicted["raster"], 4),
                round(p.predicted["raycast"], 4),
                p.choice,
            ]
        )
choices = [p.choice for p in plans]  # which way wins depends on the device's model
print(f"{len(plans)} tiles: " + ", ".join(f"{c} {choices.count(c)}" for c in sorted(set(choices))))

with Renderer(ctx, hf, "hybrid", tile_size=64, cost_model=model, adapt=False) as renderer:
    frame = renderer.render(view, tau=2 / 3, maps=True)
frame.save(out / "hybrid.png")
strategy = frame.maps["strategy"]  # per pixel: 0 sky, 1 raster tile, 2 ray-cast tile
tint = np.zeros_like(frame.colour)
tint[strategy == 1] = (40, 110, 255)
tint[strategy == 2] = (255, 140, 20)
overlay = np.where((strategy > 0)[..., None], 0.45 * frame.colour + 0.55 * tint, frame.colour)
Image.fromarray(overlay.astype(np.uint8)).save(out / "hybrid.strategy.png")
print(
    f"drew {frame.stats.tiles_raster} raster and {frame.stats.tiles_raycast} ray-cast tiles "
    f"in {frame.stats.wall_ms:.1f} ms; wrote {out / 'hybrid.png'} and {out / 'hybrid.strategy.png'}"
)
