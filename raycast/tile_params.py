"""The per-tile parameters of a ray-cast frame as one uniform buffer: the std140 ``TileParams`` block of
tile_block.glsl, one block a tile, so that a tile's draw binds a range instead of setting some 20 uniforms.

Every field is computed for all of the frame's tiles at once; only the tiles' own attributes are gathered
tile by tile.
"""

from __future__ import annotations

import numpy as np

from .maxmip import level_count
from .options import default_max_steps

# std140 offsets of TileParams (tile_block.glsl): dvec2 and vec3 align to 16 bytes, vec2 to 8, scalars to 4;
# a scalar may follow a vec3 in its last 4 bytes; the block's size rounds up to 16
TILE_BLOCK = np.dtype(
    {
        "names": [
            "dq",
            "box_lo",
            "dq_base",
            "box_hi",
            "n_cells",
            "eye_tex",
            "n_levels",
            "origin_rel",
            "tile_level",
            "ext_lo",
            "ext",
            "zr",
            "spacing",
            "uv_off",
            "uv_scale",
            "g_tile_off",
            "lod_k",
            "max_steps",
            "outer",
            "tile_index",
            "tile_id",
        ],
        "formats": [
            ("<f4", 2),
            ("<f4", 3),
            "<i4",
            ("<f4", 3),
            "<i4",
            ("<f4", 3),
            "<i4",
            ("<f4", 3),
            "<i4",
            ("<f4", 2),
            ("<f4", 2),
            ("<f4", 2),
            ("<f4", 2),
            ("<f4", 2),
            ("<f4", 2),
            ("<f4", 2),
            "<f4",
            "<i4",
            "<i4",
            "<i4",
            "<u4",
        ],
        "offsets": [0, 16, 28, 32, 44, 48, 60, 64, 76, 80, 88, 96, 104, 112, 120, 128, 136, 140, 144, 148, 152],
        "itemsize": 160,
    }
)


def outer_bits(clip: np.ndarray, hf) -> np.ndarray:
    """Per tile, the bit mask of its box sides on the terrain's outer boundary (W 1, E 2, S 4, N 8), from (B, 4)
    clip rectangles (x0, y0, x1, y1) in world metres."""
    clip = np.asarray(clip, dtype=np.float64).reshape(-1, 4)
    ox, oy = float(hf.origin[0]), float(hf.origin[1])
    w, d = hf.extent
    tol = 1e-6 * min(hf.spacing_x, hf.spacing_y)
    return (
        (np.abs(clip[:, 0] - ox) <= tol) * 1
        | (np.abs(clip[:, 2] - (ox + w)) <= tol) * 2
        | (np.abs(clip[:, 1] - oy) <= tol) * 4
        | (np.abs(clip[:, 3] - (oy + d)) <= tol) * 8
    )


def block_stride(alignment: int) -> int:
    """Bytes between two tiles' blocks in the buffer: the block's size rounded up to the driver's
    GL_UNIFORM_BUFFER_OFFSET_ALIGNMENT."""
    a = max(int(alignment), 1)
    return -(-TILE_BLOCK.itemsize // a) * a


ROW_WORDS = 17  # tile_row: clip 4, origin 3, spacing 2, zmin, zmax, offset, step, error, n, base, level


def tile_row(gt, tile) -> np.ndarray:
    """What a tile's block takes from the tile and its GPU textures alone, made once per upload: (ROW_WORDS,)
    float64 clip rectangle, origin of sample [0, 0] (world metres), spacing x and y, zmin, zmax (metres), the
    codes' offset, step and largest error (metres), cells a side, code base and pyramid level."""
    level = int(tile.key.level) if hasattr(tile, "key") else 0
    return np.array(
        [
            *tile.clip,
            *tile.origin,
            *tile.spacing_xy,
            tile.zmin,
            tile.zmax,
            gt.offset,
            gt.step,
            gt.quant_error,
            gt.n,
            gt.base,
            level,
        ],
        dtype=np.float64,
    )


def tile_params(
    items,
    eye,
    hf,
    lod_k_scale: float,
    max_steps: int | None,
    first_id: int,
    stride: int,
    rows: np.ndarray | None = None,
) -> np.ndarray:
    """The TileParams blocks (bytes laid out ``stride`` apart, as a (B, stride) uint8 array) of the frame's
    (gpu_tile, tile, selected) items for an eye (world metres); ``lod_k_scale`` is K / lod (0: no LOD),
    ``first_id`` the first tile's pre-pass ID; ``rows`` (B, ROW_WORDS), the items' ``tile_row`` where the caller
    keeps them."""
    b = len(items)
    if rows is None:
        rows = np.stack([tile_row(gt, t) for gt, t, _ in items]) if b else np.zeros((0, ROW_WORDS))
    clip, org, sp, z, g = rows[:, 0:4], rows[:, 4:7], rows[:, 7:9], rows[:, 9:11], rows[:, 11:14]
    ints = rows[:, 14:17].astype(np.int64)
    eye = np.asarray(eye, dtype=np.float64)
    ox, oy = float(hf.origin[0]), float(hf.origin[1])
    ext_w, ext_d = hf.extent
    pad = 1e-3 * sp.max(axis=1) + 0.01
    zq = g[:, 2]  # the codes' heights lie within zq of the tile's bounds
    out = np.zeros(b, TILE_BLOCK)
    out["dq"] = g[:, :2]
    out["box_lo"] = np.stack([clip[:, 0] - pad, clip[:, 1] - pad, z[:, 0] - zq - pad], axis=1) - eye
    out["box_hi"] = np.stack([clip[:, 2] + pad, clip[:, 3] + pad, z[:, 1] + zq + pad], axis=1) - eye
    out["n_cells"], out["dq_base"], out["tile_level"] = ints[:, 0], ints[:, 1], ints[:, 2]
    per_n = {
        int(n): (level_count(int(n)) - 1, max_steps or default_max_steps(int(n))) for n in set(ints[:, 0].tolist())
    }
    out["n_levels"] = [per_n[n][0] for n in ints[:, 0].tolist()]
    out["eye_tex"] = np.column_stack(
        [(eye[0] - org[:, 0]) / sp[:, 0], (eye[1] - org[:, 1]) / sp[:, 1], eye[2] - org[:, 2]]
    )
    out["origin_rel"] = org - eye
    out["ext_lo"] = (clip[:, :2] - org[:, :2]) / sp  # texels from the tile's origin
    out["ext"] = (clip[:, 2:] - org[:, :2]) / sp
    out["zr"] = np.column_stack([z[:, 0] - zq - org[:, 2], z[:, 1] + zq - org[:, 2]])
    out["spacing"] = sp
    out["uv_off"] = np.column_stack([(org[:, 0] - ox) / ext_w, (org[:, 1] - oy) / ext_d])
    out["uv_scale"] = sp / np.array([ext_w, ext_d])
    out["g_tile_off"] = np.column_stack([(org[:, 0] - ox) / hf.spacing_x, (org[:, 1] - oy) / hf.spacing_y])
    out["lod_k"] = sp.max(axis=1) * lod_k_scale
    out["max_steps"] = [per_n[n][1] for n in ints[:, 0].tolist()]
    out["outer"] = outer_bits(clip, hf)
    out["tile_index"] = np.arange(b)
    out["tile_id"] = first_id + np.arange(b)
    blocks = np.zeros((b, stride), np.uint8)
    blocks[:, : TILE_BLOCK.itemsize] = out.view(np.uint8).reshape(b, TILE_BLOCK.itemsize)
    return blocks
