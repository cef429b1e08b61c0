"""Maximum mipmaps of a tile: level 0 bounds each cell, level l is the 2x2 maximum of level l-1, down to 1x1.

Texel space of a tile with N cells a side ((N+1)² height samples): level-0 texel (i, j) is cell (i, j), the
square [j, j+1] x [i, i+1]; it holds the largest of the cell's four corner heights, so it bounds every
reconstruction that interpolates those corners (planes, linear planes, triangles, bilinear). Level l texel
(i, j) covers cells [i*2^l, (i+1)*2^l) x [j*2^l, (j+1)*2^l). Rows run south to north.

On the GPU a tile is its (N+1)² 16-bit height codes (hybrid.tiles.quantize) in an R16UI texture and its max
mipmap without level 0 (levels 1..log2 N) in a storage buffer (raycast.mip_buffer); the traversal takes level 0
from the four corner heights. The shadow rays' whole-terrain grid keeps its max mipmap in an (N/2)² R16UI texture
with log2(N) levels whose level k holds max-mip level k+1, built by the GPU builder (compute shaders) below.
Dequantisation is monotone, so the maximum of codes is the code of the maximum, and the builder gives exactly
``maxmip_levels`` of the codes. Bytes of a tile: 2 (N+1)² + 2 (N²/4) 4/3, about 2.67 a sample.
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.gl.context import read_r16ui_level, red_mip_texture
from hybrid.gl.programs import compute_shader
from hybrid.terrain.edits import Window


def _check_heights(heights) -> np.ndarray:
    h = np.asarray(heights)
    if h.ndim != 2 or h.shape[0] != h.shape[1] or h.shape[0] < 3:
        raise TerrabenchError(f"heights must be a square (N+1, N+1) array with N >= 2, got shape {h.shape}")
    n = h.shape[0] - 1
    if n & (n - 1):
        raise TerrabenchError(f"heights must have N+1 samples a side with N a power of two, got N = {n}")
    return h if h.dtype == np.uint16 else h.astype(np.float32, copy=False)


def level_count(n: int) -> int:
    """Number of max-mip levels of a tile of n cells a side (n a power of two): log2(n) + 1."""
    if isinstance(n, bool) or int(n) != n or n < 1 or int(n) & (int(n) - 1):
        raise TerrabenchError(f"cells per side must be a power of two >= 1, got {n!r}")
    return int(n).bit_length()


def maxmip_levels(heights) -> list[np.ndarray]:
    """Max-mip pyramid of (N+1)² heights: [N x N cell maxima, N/2 x N/2, ..., 1 x 1]; uint16 codes stay uint16,
    anything else is float32 metres."""
    h = _check_heights(heights)
    base = np.maximum(np.maximum(h[:-1, :-1], h[:-1, 1:]), np.maximum(h[1:, :-1], h[1:, 1:]))
    levels = [np.ascontiguousarray(base)]
    while levels[-1].shape[0] > 1:
        a = levels[-1]
        m = a.shape[0] // 2
        levels.append(np.ascontiguousarray(a.reshape(m, 2, m, 2).max(axis=(1, 3))))
    return levels


def texel_windows(n: int, win: Window) -> list[tuple[int, int, int, int]]:
    """Per stored level (max-mip levels 1 .. log2 n) of an n-cell tile, the texels (r0, r1, c0, c1) whose value
    can change when height samples in ``win`` (tile-local rows and columns) change: a level-1 texel p reads
    samples 2p .. 2p + 2, a coarser one its 2x2 texels below."""
    half = n // 2
    r0, r1 = max((win.i0 - 1) // 2, 0), min((win.i1 - 1) // 2 + 1, half)
    c0, c1 = max((win.j0 - 1) // 2, 0), min((win.j1 - 1) // 2 + 1, half)
    out = []
    for _ in range(level_count(n) - 1):
        out.append((r0, r1, c0, c1))
        r0, r1, c0, c1 = r0 // 2, (r1 - 1) // 2 + 1, c0 // 2, (c1 - 1) // 2 + 1
    return out


def update_levels(levels: list[np.ndarray], heights, win: Window) -> None:
    """Refill ``maxmip_levels``' levels 1.. in place over the texels a window of changed samples reaches
    (``texel_windows``); level 0 is refilled over the window's cells."""
    h = _check_heights(heights)
    n = h.shape[0] - 1
    a0, a1, b0, b1 = max(win.i0 - 1, 0), min(win.i1, n), max(win.j0 - 1, 0), min(win.j1, n)
    s = h[a0 : a1 + 1, b0 : b1 + 1]
    levels[0][a0:a1, b0:b1] = np.maximum(np.maximum(s[:-1, :-1], s[:-1, 1:]), np.maximum(s[1:, :-1], s[1:, 1:]))
    for k, (r0, r1, c0, c1) in enumerate(texel_windows(n, win), start=1):
        below = levels[k - 1][2 * r0 : 2 * r1, 2 * c0 : 2 * c1]
        m0, m1 = r1 - r0, c1 - c0
        levels[k][r0:r1, c0:c1] = below.reshape(m0, 2, m1, 2).max(axis=(1, 3))


def maxmip_nbytes(n: int, itemsize: int = 2) -> int:
    """Bytes of the stored max mipmap of an n-cell tile (levels 1..log2 n) of ``itemsize``-byte texels (2: R16UI
    codes, 4: R32F metres): itemsize (n²/4 + n²/16 + ... + 1)."""
    return sum(itemsize * (n >> l) ** 2 for l in range(1, level_count(n)))


def mip_buffer_nbytes(n: int, itemsize: int = 2) -> int:
    """Bytes of the storage buffer holding an n-cell tile's max mipmap (``raycast.mip_buffer``): its texels padded
    to whole 32-bit words."""
    return -(-maxmip_nbytes(n, itemsize) // 4) * 4


def heights_nbytes(n: int, itemsize: int = 2) -> int:
    """Bytes of an n-cell tile's height texture of ``itemsize``-byte texels: itemsize (n+1)²."""
    return itemsize * (int(n) + 1) ** 2


def tile_nbytes(n: int, itemsize: int = 2) -> int:
    """GPU bytes of one n-cell ray-cast tile of ``itemsize``-byte texels: its height texture and its max mipmap's
    storage buffer."""
    return heights_nbytes(n, itemsize) + mip_buffer_nbytes(n, itemsize)


def bytes_per_sample(n: int, itemsize: int = 2) -> float:
    """GPU bytes a height sample of an n-cell tile, max mipmap included: tile_nbytes / (n+1)²."""
    return tile_nbytes(n, itemsize) / (int(n) + 1) ** 2


class MaxMipBuilder:
    """Compute-shader programs that fill a grid's max-mip texture from its height-code texture, level by level."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.base = compute_shader(ctx, "raycast", "maxmip_base.comp.glsl")
        self.reduce = compute_shader(ctx, "raycast", "maxmip_reduce.comp.glsl")

    def allocate(self, n: int):
        """An R16UI (n/2)² texture with log2(n) mip levels allocated (contents undefined)."""
        return red_mip_texture(self.ctx, n // 2, level_count(n) - 1)

    def build(self, height_tex, n: int, out_tex=None):
        """Fill (or allocate and fill) the max-mip texture of an R16UI (n+1)² height texture; returns it."""
        tex = out_tex if out_tex is not None else self.allocate(n)
        self._fill(height_tex, tex, n, texel_windows(n, Window(0, n + 1, 0, n + 1)))
        return tex

    def _fill(self, height_tex, tex, n: int, windows) -> None:
        """Dispatch the base pass and the reductions over one (r0, r1, c0, c1) texel window per stored level."""
        height_tex.use(0)
        self.base["heights"].value = 0
        for k, (r0, r1, c0, c1) in enumerate(windows):
            prog = self.base if k == 0 else self.reduce
            if k:
                self.ctx.memory_barrier()
                tex.bind_to_image(0, read=True, write=False, level=k - 1)
            tex.bind_to_image(1, read=False, write=True, level=k)
            prog["extent"].value = (c1 - c0, r1 - r0)
            prog["first"].value = (c0, r0)
            prog.run(-(-(c1 - c0) // 8), -(-(r1 - r0) // 8), 1)
        self.ctx.memory_barrier()

    def release(self) -> None:
        """Free the programs."""
        self.base.release()
        self.reduce.release()


def read_maxmip(tex, n: int) -> list[np.ndarray]:
    """Read every stored level of a GPU max-mip texture back as uint16 codes: max-mip levels 1..log2 n."""
    return [read_r16ui_level(tex, k) for k in range(level_count(n) - 1)]
