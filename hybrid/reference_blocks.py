"""The reference surface cut into blocks that each fit one GL texture, and which of them a view can see.

A grid of any size is drawn block by block: each block is at most ``side`` samples a side (the context's
texture limit or less), neighbours share their edge row or column of samples, so the blocks' triangles are
exactly the whole grid's, two a cell, with no seam. Each block's box (its samples' extent and height range) is
tested against the view's frustum, so a view of part of a large grid reads and draws only the blocks it shows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.tiles.tiletree import box_classes, corner_planes

DEFAULT_BLOCK_SAMPLES = 2049  # 2048² cells a block: a 96 MiB shared index buffer at most


@dataclass(frozen=True)
class Block:
    """Sample rows r0..r1-1 and columns c0..c1-1 of the grid (rows south to north)."""

    r0: int
    r1: int
    c0: int
    c1: int

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the block's samples."""
        return self.r1 - self.r0, self.c1 - self.c0


def _spans(samples: int, side: int) -> list[tuple[int, int]]:
    step = side - 1
    return [(s, min(s + side, samples)) for s in range(0, samples - 1, step)]


def reference_blocks(rows: int, cols: int, side: int) -> list[Block]:
    """Blocks of at most ``side`` samples a side that cover a rows x cols grid, sharing their edge samples."""
    if side < 2:
        raise TerrabenchError(f"a reference block needs at least 2 samples a side, got {side}")
    if rows < 2 or cols < 2:
        raise TerrabenchError(f"the reference needs a grid of at least 2x2 samples, got {cols}x{rows}")
    return [Block(r0, r1, c0, c1) for r0, r1 in _spans(rows, side) for c0, c1 in _spans(cols, side)]


def block_bounds(hf, blocks: list[Block]) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest height (metres, relative to the origin z) of each block's samples: read from the
    heights where they are in memory, from a tile store's per-tile bounds (conservative) otherwise."""
    h = hf.heights
    if isinstance(h, np.ndarray):
        lo = np.array([np.min(h[b.r0 : b.r1, b.c0 : b.c1]) for b in blocks], dtype=np.float64)
        hi = np.array([np.max(h[b.r0 : b.r1, b.c0 : b.c1]) for b in blocks], dtype=np.float64)
        return lo, hi
    r0, r1, c0, c1 = (np.array([getattr(b, k) for b in blocks]) for k in ("r0", "r1", "c0", "c1"))
    return hf.window_extremes(r0, r1 - 1, c0, c1 - 1)


def visible_blocks(hf, blocks: list[Block], lo: np.ndarray, hi: np.ndarray, view) -> np.ndarray:
    """Indices of the blocks whose box meets the view's frustum (boxes in world metres, tested eye-relative by the
    tile selection's own test, ``hybrid.tiles.tiletree.box_classes``)."""
    ox, oy, oz = (float(v) for v in hf.origin)
    c0, c1 = np.array([b.c0 for b in blocks], float), np.array([b.c1 - 1 for b in blocks], float)
    r0, r1 = np.array([b.r0 for b in blocks], float), np.array([b.r1 - 1 for b in blocks], float)
    boxes = np.stack(
        [
            ox + c0 * hf.spacing_x,
            oy + r0 * hf.spacing_y,
            oz + lo,
            ox + c1 * hf.spacing_x,
            oy + r1 * hf.spacing_y,
            oz + hi,
        ],
        axis=1,
    )
    eye = np.asarray(view.eye, dtype=np.float64)
    classes = box_classes(boxes - np.concatenate([eye, eye]), *corner_planes(view.frustum_planes_rel()))
    return np.flatnonzero(classes >= 0)
