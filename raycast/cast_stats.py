"""The ray caster's per-tile counters: their layout in the storage buffer (the shaders' only source of it) and
the frame's counters read back from it.

Each tile's counters are kept in STAT_SLOTS copies, one per screen bin (modulo), so that the fragments of one
tile rarely add to the same words at once; reading back sums the copies (``max_steps``: their maximum).
"""

from __future__ import annotations

import numpy as np

STAT_FIELDS = ("rays", "hits", "steps", "max_steps", "capped", "shadow_rays", "shadow_steps", "shadow_capped")
STAT_SLOTS = 64  # copies of each tile's counters (one per screen bin, modulo)
STAT_STRIDE = 64  # bytes between copies (16 uints: one cache line, 8 used)
STAT_BIN_SHIFT = 6  # screen bins of 2^6 = 64 pixels a side
STATS_BINDING, TILE_PARAMS_BINDING = 0, 3  # storage binding of the counters, uniform binding of a tile's block
MIPS_BINDING = 1  # storage binding of the cast tile's max mipmap (raycast.maxmip.mip_buffer)
LAYOUT_DEFINES = {
    "STAT_SLOTS": STAT_SLOTS,
    "STAT_WORDS": STAT_STRIDE // 4,
    "STAT_BIN_SHIFT": STAT_BIN_SHIFT,
    "STATS_BINDING": STATS_BINDING,
    "TILE_PARAMS_BINDING": TILE_PARAMS_BINDING,
    "MIPS_BINDING": MIPS_BINDING,
}
"""The layout above as the shaders' defines (raycast.frag.glsl, tile_block.glsl, traverse.glsl): their only source of it."""


def read_tile_stats(buf, n_items: int) -> np.ndarray:
    """Per tile, its counters (n_items, len(STAT_FIELDS)) int64 from the counters' buffer: copies summed,
    ``max_steps`` their maximum."""
    raw = np.frombuffer(buf.read(size=STAT_SLOTS * STAT_STRIDE * n_items), dtype=np.uint32)
    raw = raw.reshape(n_items, STAT_SLOTS, STAT_STRIDE // 4)[:, :, : len(STAT_FIELDS)].astype(np.int64)
    st = raw.sum(axis=1)
    st[:, 3] = raw[:, :, 3].max(axis=1)
    return st


def frame_counters(tile_stats: np.ndarray | None, opts, items, grid) -> dict:
    """The frame's counters: rays, hits and steps summed over the tiles' counters (``tile_stats``; None without
    the ``stats`` option or tiles), tiles cast, the largest quantisation error, and the shadow grid's figures."""
    counters: dict[str, int | float] = {"rays": 0, "hits": 0, "steps": 0, "max_steps": 0, "capped": 0}
    if tile_stats is not None:
        tot = tile_stats.sum(axis=0)
        counters = {f: int(tot[i]) for i, f in enumerate(STAT_FIELDS)}
        counters["max_steps"] = int(tile_stats[:, 3].max())
        counters["mean_steps"] = counters["steps"] / max(counters["rays"], 1)
        if not opts.shadows:
            for f in ("shadow_rays", "shadow_steps", "shadow_capped"):
                counters.pop(f)
    counters["tiles_cast"] = len(items)
    counters["quant_error_max_m"] = max((float(g.quant_error) for g, _t, _s in items), default=0.0)
    if grid is not None:
        counters["shadow_grid_bytes"] = grid.nbytes
        counters["shadow_quant_error_m"] = float(grid.tex.quant_error)
    return counters
