"""Prepare a tile store (terrain kept on disk) and stream it while flying over it.

    python docs/examples/05_tile_store.py [OUT_DIR]

A store is a Zarr folder with every pyramid level, tile errors, the raster strategies' node arrays and a
manifest; rendering reads only the tiles a view selects. The command-line form is
`terrabench prepare --synthetic 257 --synthetic-spacing 20 --tile-size 32 --out fbm.store`.
Writes OUT_DIR/fbm.store/ and OUT_DIR/store_frame.png.
"""

import sys
from pathlib import Path

from hybrid import Renderer, preset, shared_context
from hybrid.terrain.grid_sources import FractalSource
from hybrid.terrain.stored import open_store
from hybrid.tiles.store import prepare_store

out = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
out.mkdir(parents=True, exist_ok=True)

source = FractalSource(257, 0, 20.0)  # seeded fractal terrain: 257² samples, 20 m spacing
store = prepare_store(source, out / "fbm.store", tile_size=32)  # written band by band, resumable
hf = open_store(store)  # heights stay on disk; tiles are read as views need them

flight = preset("flyover", hf, frames=4, width=320, height=180)
# upload_budget_ms: uploads run inside each frame until 8 ms are spent; tiles still waiting are drawn from a
# resident coarser ancestor (fallback tiles) and arrive in later frames.
with Renderer(shared_context(), hf, "hybrid", tile_size=32, upload_budget_ms=8.0) as renderer:
    for k in range(4):
        frame = renderer.render(flight.view(k), tau=2 / 3)
        s = frame.stats
        print(
            f"frame {k}: {s.tiles} tiles, {s.uploads} uploaded, {s.fallback_tiles} drawn from an ancestor, "
            f"{s.gpu_bytes / 2**20:.1f} MiB on the GPU, {s.wall_ms:.1f} ms"
        )
frame.save(out / "store_frame.png")
print(f"wrote {store} and {out / 'store_frame.png'}")
