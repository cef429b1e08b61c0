"""Tilelet fan surfaces of the one quadtree over a square grid, evaluated on any window of it.

A node of level m covers 2^(m+1) cells of an n-cell square grid (n a power of two); its full fan splits each of
its four quadrants along the diagonal through the centre post (posts every 2^m samples, diagonals alternating
with the parity of the post quad), its stitched fan is the four triangles centre-corner-corner. Samples on a node
border belong to the node north or east of it, except on the grid's last row and column. Every sample's value is
computed with the same floating-point operations whatever window holds it, so a grid's node errors can be
measured window by window (the tile store's node arrays, ``hybrid.tiles.store_nodes``) with exactly the values
``raster.quadtree.error_pyramid`` gives on the whole grid.

This module sits below the strategies because ``prepare`` (``hybrid.tiles``) writes what the raster strategies
read; ``raster.quadtree`` re-exports GPU_BETA.
"""

from __future__ import annotations

import numpy as np

GPU_BETA = 0.9
"""beta of the GPU-selected strategies: a node's effective error grows by 1/beta a level, so 0.9 models fewer
triangles than 0.7 (23 % on the Puget flyover) over a shorter morph (the tolerance falls 10 % during it)."""


def fans_at(h: np.ndarray, r0: int, c0: int, rows: np.ndarray, cols: np.ndarray, m: int, n: int):
    """(full, stitched) fan heights (metres, float64) of level-m nodes at samples (rows x cols) of an n-cell grid.

    ``h`` holds the grid's samples rows r0.., columns c0.. (a window, float64); ``rows``/``cols`` are grid indices
    inside it. Posts outside the window are read at its edge: that happens only for samples on the window's last
    row or column, where those posts are weighted by an exact zero (heights must be finite).
    """
    k = 1 << m
    s = 2 * k

    def post(i, lo, size):
        return np.clip(i - lo, 0, size - 1)

    R, C = h.shape
    # full fan: quads of the post grid, diagonal SW-NE where (I + J) is even, NW-SE where odd
    Ir, Ic = np.minimum(rows // k, n // k - 1), np.minimum(cols // k, n // k - 1)
    fi, fj = ((rows - Ir * k) / k)[:, None], ((cols - Ic * k) / k)[None, :]
    a0, a1 = post(Ir * k, r0, R), post(Ir * k + k, r0, R)
    b0, b1 = post(Ic * k, c0, C), post(Ic * k + k, c0, C)
    h00, h01 = h[np.ix_(a0, b0)], h[np.ix_(a0, b1)]
    h10, h11 = h[np.ix_(a1, b0)], h[np.ix_(a1, b1)]
    main = np.where(fj >= fi, h00 + fj * (h01 - h00) + fi * (h11 - h01), h00 + fi * (h10 - h00) + fj * (h11 - h10))
    anti = np.where(
        fi + fj <= 1.0,
        h00 + fj * (h01 - h00) + fi * (h10 - h00),
        h11 + (1.0 - fj) * (h10 - h11) + (1.0 - fi) * (h01 - h11),
    )
    del h00, h01, h10, h11
    odd = ((Ir[:, None] + Ic[None, :]) & 1).astype(bool)
    full = np.where(odd, anti, main)
    del main, anti
    # stitched fan: four triangles around the centre, local coordinates u (east), v (north) in [0, 2]
    Ar, Ac = np.minimum(rows // s, n // s - 1), np.minimum(cols // s, n // s - 1)
    v, u = ((rows - Ar * s) / k)[:, None], ((cols - Ac * s) / k)[None, :]
    s0, s1, sc = post(Ar * s, r0, R), post(Ar * s + s, r0, R), post(Ar * s + k, r0, R)
    w0, w1, wc = post(Ac * s, c0, C), post(Ac * s + s, c0, C), post(Ac * s + k, c0, C)
    sw, se = h[np.ix_(s0, w0)], h[np.ix_(s0, w1)]
    nw, ne = h[np.ix_(s1, w0)], h[np.ix_(s1, w1)]
    c = h[np.ix_(sc, wc)]
    bottom = sw + 0.5 * u * (se - sw) + v * (c - 0.5 * (sw + se))
    right = se + 0.5 * v * (ne - se) + (2.0 - u) * (c - 0.5 * (se + ne))
    top = nw + 0.5 * u * (ne - nw) + (2.0 - v) * (c - 0.5 * (nw + ne))
    left = sw + 0.5 * v * (nw - sw) + u * (c - 0.5 * (sw + nw))
    below_main = v <= u  # below the SW-NE diagonal
    below_anti = v <= 2.0 - u  # below the NW-SE diagonal
    stitched = np.where(below_main, np.where(below_anti, bottom, right), np.where(below_anti, left, top))
    return full, stitched


def fan_deviations(
    h: np.ndarray, r0: int, c0: int, rows: np.ndarray, cols: np.ndarray, m: int, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """(|full - h|, |stitched - h|) in metres of level-m nodes at samples (rows x cols), as ``fans_at``."""
    full, stitched = fans_at(h, r0, c0, rows, cols, m, n)
    own = h[np.ix_(rows - r0, cols - c0)]
    return np.abs(full - own), np.abs(stitched - own)


def fan_deviation(h: np.ndarray, r0: int, c0: int, rows: np.ndarray, cols: np.ndarray, m: int, n: int) -> np.ndarray:
    """max(|full - h|, |stitched - h|) in metres of level-m nodes at samples (rows x cols), as ``fans_at``."""
    return np.maximum(*fan_deviations(h, r0, c0, rows, cols, m, n))


def side_maxima(dev: np.ndarray, m: int, row_offset: int = 0) -> np.ndarray:
    """(4, Nr, Nc): per level-m node, the max of a sample array over each triangle of the stitched fan, sides W, E,
    S, N (each triangle with its border samples). ``dev`` holds (rows + 1) x (n + 1) samples of whole node columns:
    whole node rows (Nr = rows / node side), or, fewer rows than a node's side, a part of one node row starting
    ``row_offset`` samples into it (Nr = 1; its maxima cover that part)."""
    rows, n = dev.shape[0] - 1, dev.shape[1] - 1
    k, s = 1 << m, 2 << m
    sr = min(s, rows)
    Nr, Nc = rows // sr, n // s
    # each node's samples, its borders included (shared with its neighbours): (Nr, sr + 1, Nc, s + 1)
    ri = (np.arange(Nr)[:, None] * sr + np.arange(sr + 1)[None, :]).ravel()
    ci = (np.arange(Nc)[:, None] * s + np.arange(s + 1)[None, :]).ravel()
    win = dev[np.ix_(ri, ci)].reshape(Nr, sr + 1, Nc, s + 1)
    v, u = ((np.arange(sr + 1) + row_offset) / k)[:, None], (np.arange(s + 1) / k)[None, :]  # local coordinates
    out = np.empty((4, Nr, Nc))
    for i, mask in enumerate(
        ((v >= u) & (v <= 2.0 - u), (v <= u) & (v >= 2.0 - u), (v <= u) & (v <= 2.0 - u), (v >= u) & (v >= 2.0 - u))
    ):
        out[i] = win.max(axis=(1, 3), where=mask[None, :, None, :], initial=0.0)
    return out


def with_cell_centres(h: np.ndarray, sides: np.ndarray) -> np.ndarray:
    """Level-0 side errors (4, N, N) (metres) of a (2N + 1)² sample window raised where dropping a midpoint changes
    the SE and NW cells (whose fan diagonal runs from the centre post to the corner, where the reference's runs
    SW-NE): by the distance at the cell's centre between the two diagonals with the midpoints at their heights (a
    leaf keeping every midpoint draws the reference's cells; where a side's error is 0 the leaf dropping it equals
    the reference: samples and these crossings are every vertex of the overlay), and by that distance with the
    midpoints on their edges (|centre post - mean of SW and NE corners| / 2), which a drop makes jump (by at most
    beta times the bound, as the drop waits until the side meets it by beta)."""
    se, nw = _centre_terms(h)
    out = sides.copy()
    out[0] = np.maximum(out[0], nw)  # W
    out[1] = np.maximum(out[1], se)  # E
    out[2] = np.maximum(out[2], se)  # S
    out[3] = np.maximum(out[3], nw)  # N
    return out


def _centre_terms(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(SE, NW) per level-0 node of a (2N + 1)² sample window: ``with_cell_centres``' terms of its SE and NW cells."""
    c = h[1::2, 1::2]
    se = np.abs(0.5 * (c + h[0:-1:2, 2::2]) - 0.5 * (h[0:-1:2, 1::2] + h[1::2, 2::2]))
    nw = np.abs(0.5 * (c + h[2::2, 0:-1:2]) - 0.5 * (h[1::2, 0:-1:2] + h[2::2, 1::2]))
    flip = 0.5 * np.abs(c - 0.5 * (h[0:-1:2, 0:-1:2] + h[2::2, 2::2]))
    return np.maximum(se, flip), np.maximum(nw, flip)


def cell_centre_error(h: np.ndarray) -> np.ndarray:
    """(N, N) per level-0 node of a (2N + 1)² sample window: the larger of its cell-centre terms (metres), which a
    level-0 node's error in the combined form (both fans in one error) includes, so that it bounds every side."""
    return np.maximum(*_centre_terms(h))


def facing_side_errors(sides: np.ndarray) -> np.ndarray:
    """(N, N): per node, the largest side error (``side_maxima``) of the same-size nodes outside its parent that
    face it across the parent's border (W neighbour's E side, and so on); 0 where none."""
    W, E, S, N = sides
    out = np.zeros_like(W)
    out[:, 2::2] = E[:, 1:-1:2]
    out[:, 1:-1:2] = np.maximum(out[:, 1:-1:2], W[:, 2::2])
    out[2::2, :] = np.maximum(out[2::2, :], N[1:-1:2, :])
    out[1:-1:2, :] = np.maximum(out[1:-1:2, :], S[2::2, :])
    return out


def cell_max(dev: np.ndarray) -> np.ndarray:
    """Per cell: the max of a sample array over the cell's four corners ((r-1) x (c-1))."""
    return np.maximum(np.maximum(dev[:-1, :-1], dev[:-1, 1:]), np.maximum(dev[1:, :-1], dev[1:, 1:]))


def block2(a: np.ndarray, fn) -> np.ndarray:
    """fn (np.max, np.min) over 2 x 2 blocks of an array with even sides."""
    return fn(a.reshape(a.shape[0] // 2, 2, a.shape[1] // 2, 2), axis=(1, 3))


def dilate4(a: np.ndarray) -> np.ndarray:
    """Max of each element and its four edge neighbours (no wrap)."""
    out = a.copy()
    np.maximum(out[1:], a[:-1], out=out[1:])
    np.maximum(out[:-1], a[1:], out=out[:-1])
    np.maximum(out[:, 1:], a[:, :-1], out=out[:, 1:])
    np.maximum(out[:, :-1], a[:, 1:], out=out[:, :-1])
    return out


def grow3(a: np.ndarray, fn) -> np.ndarray:
    """fn (np.minimum, np.maximum) over each element's 3x3 neighbourhood (edges repeat)."""
    p = np.pad(a, 1, mode="edge")
    out = a.copy()
    n0, n1 = a.shape
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            out = fn(out, p[dy : dy + n0, dx : dx + n1])
    return out
