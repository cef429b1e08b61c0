"""Render one view of the bundled Puget Sound terrain with the raster strategy, and save it.

    python docs/examples/01_render_a_view.py [OUT_DIR]

Writes OUT_DIR/raster.png and OUT_DIR/raster.depth.npy (distance in metres, inf where there is no terrain).
"""

import sys
from pathlib import Path

from hybrid import Renderer, preset, puget, shared_context

out = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
out.mkdir(parents=True, exist_ok=True)

hf = puget(size=257)  # a 257² window around Mount Rainier, 160 m spacing
view = preset("flyover", hf, frames=4, width=320, height=180).view(1)  # frame 1 of a 4-frame flyover

with Renderer(shared_context(), hf, "raster", tile_size=64) as renderer:
    frame = renderer.render(view, tau=2 / 3)  # screen-space error bound: 2/3 pixel
png, depth = frame.save(out / "raster.png")
s = frame.stats
print(
    f"wrote {png} and {depth}: {s.wall_ms:.1f} ms, {s.tiles} tiles, "
    f"terrain on {100 * frame.mask.mean():.0f} % of pixels"
)
