"""A ray-cast tile's max mipmap in a storage buffer, as the cast shader reads it (raycast/traverse.glsl, rc_code).

Max-mip levels 1..log2 N of an N-cell tile lie one after another, each row by row (row 0 south), so level l starts
at texel (N² - 4 (N >> l)²) / 3: the host's flat array of levels (``raycast.mip_loops.code_mip_levels``) as it
is. uint16 codes are two to a 32-bit word (the low half first, as little-endian bytes lay them), float32 metres one;
the buffer is padded to whole words. A fetch from it is an index and a load, where a texture fetch at a per-lane
mip level first computes that level's offset and size (on a CPU rasterizer, most of a traversal step's fetch).
"""

from __future__ import annotations

import numpy as np

from .maxmip import level_count, mip_buffer_nbytes


def level_starts(n: int) -> list[int]:
    """Texel offset of each max-mip level 1..log2 n of an n-cell tile in its buffer: (n² - 4 (n >> l)²) / 3."""
    return [(n * n - 4 * (n >> lev) ** 2) // 3 for lev in range(1, level_count(n))]


def level_views(flat: np.ndarray, n: int) -> tuple[np.ndarray, ...]:
    """The (n >> l)² views of max-mip levels 1..log2 n of an n-cell tile held one after another in ``flat`` (the
    buffer's layout, as ``code_mip_levels`` makes it)."""
    return tuple(flat[s : s + (n >> lev) ** 2].reshape(n >> lev, n >> lev) for lev, s in enumerate(level_starts(n), 1))


def mip_buffer(ctx, mips):
    """A storage buffer holding a tile's max-mip levels 1..log2 N (``code_mips``), padded to whole 32-bit words:
    each level written at its start (``write_mip_rows``)."""
    buf = ctx.buffer(reserve=mip_buffer_nbytes(int(mips[0].shape[0]) * 2, mips[0].itemsize))
    write_mip_rows(buf, mips)
    return buf


def read_mip_buffer(buf, n: int, dtype=np.uint16) -> tuple[np.ndarray, ...]:
    """A tile's max-mip levels 1..log2 n read back from its buffer: (n >> l)² arrays of ``dtype`` texels."""
    return level_views(np.frombuffer(buf.read(), dtype=dtype), n)


def write_mip_rows(buf, mips, windows=None) -> None:
    """Write host max-mip levels (levels 1..log2 N) into a tile's buffer: each level whole, or, per level, the whole
    rows r0..r1 of its (r0, r1, c0, c1) texel window in ``windows`` (one contiguous write a level)."""
    n = int(mips[0].shape[0]) * 2
    for m, start, win in zip(mips, level_starts(n), windows if windows is not None else [None] * len(mips)):
        r0, r1 = (0, m.shape[0]) if win is None else (int(win[0]), int(win[1]))
        if r1 > r0 and (win is None or win[3] > win[2]):
            rows = np.ascontiguousarray(m[r0:r1])
            buf.write(rows, offset=(start + r0 * m.shape[1]) * rows.itemsize)
