"""16-bit heights: per-tile codes q in [0, 65535] with h = float32(offset + step * (q + base)), in metres.

Heights are float32 metres relative to the terrain's origin z, as in a Tile. Two cases:
- a source on a known step (``source_step = (step, offset)``: the loader made every height as
  float32(offset + step * k) for an integer k, as from a 16-bit PNG at 0.1 m a unit) whose tile spans at most
  65535 steps: base = the tile's smallest k, q = k - base; the dequantised heights equal the source bit for
  bit (quantisation error 0). The arithmetic is float64, rounded to float32 once, as the loader did
  (float32 arithmetic would round k * step differently for about one k in five);
- otherwise: offset = the tile's lowest height, step = range / 65535, base = 0; the error (at most step/2
  plus float32 rounding) is measured. A flat tile gets step 1 and q = 0.
The ray caster (raycast) uploads the codes; the pyramid bounds the error of every tile (``error_bound``)
so that tile selection can add it to the geometric error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

Q_MAX = 65535
_HALF_ULP = 2.0**-24  # float32 rounding of a dequantised height: at most |h| * 2^-24


@dataclass(frozen=True)
class Quantized:
    """A tile's 16-bit codes and how to turn them back into metres (relative to the terrain's origin z)."""

    q: np.ndarray  # uint16, the heights' shape
    offset: float  # metres
    step: float  # metres per code unit
    base: int  # added to q before scaling
    error: float  # largest |h - dequantised| over the tile, metres (measured)

    @property
    def exact(self) -> bool:
        """True when the dequantised heights equal the source heights bit for bit."""
        return self.error == 0.0


def dequantize(q, offset: float, step: float, base: int = 0) -> np.ndarray:
    """Float32 heights (metres, relative to origin z) of codes q: float32(offset + step * (q + base)) in float64."""
    return (float(offset) + float(step) * (np.asarray(q, dtype=np.float64) + float(base))).astype(np.float32)


def _on_step(h: np.ndarray, step: float, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Integer steps k of float32 heights and where float32(offset + step * k) gives the height back exactly."""
    k = np.rint((h.astype(np.float64) - offset) / step)
    return k, (offset + step * k).astype(np.float32) == h


def quantize(heights, source_step: tuple[float, float] | None = None) -> Quantized:
    """16-bit codes of float32 heights (metres, relative to origin z): exact on the source's step, else range/65535.

    One compiled pass per question over the samples (``hybrid.tiles.quantize_loops``)."""
    from .quantize_loops import height_range, range_codes, step_codes

    h = np.ascontiguousarray(heights, dtype=np.float32)
    if h.ndim != 2:
        h = h.reshape(1, -1)
    lo, hi = height_range(h)
    shape = np.shape(heights)
    if source_step is not None:
        step, offset = (float(v) for v in source_step)
        q, base, ok = step_codes(h, step, offset, float(Q_MAX))
        if ok:
            return Quantized(q.reshape(shape), offset, step, int(base), 0.0)
    if hi == lo:
        return Quantized(np.zeros(shape, np.uint16), lo, 1.0, 0, 0.0)
    step = (hi - lo) / Q_MAX
    q, err = range_codes(h, lo, step, float(Q_MAX))
    return Quantized(q.reshape(shape), lo, step, 0, float(err))


def quantized_heights(heights, source_step: tuple[float, float] | None = None) -> np.ndarray:
    """Float32 heights (metres, relative to origin z) as the ray caster sees them: quantised and dequantised."""
    z = quantize(heights, source_step)
    return dequantize(z.q, z.offset, z.step, z.base)


def error_bound(zmin, zmax, exact=False) -> np.ndarray:
    """Upper bound (metres) on ``quantize``'s error for tiles whose heights lie in [zmin, zmax] (metres, relative
    to origin z); ``exact`` marks tiles known to be on the source's step within 65535 steps (bound 0)."""
    zmin, zmax = np.asarray(zmin, np.float64), np.asarray(zmax, np.float64)
    b = (zmax - zmin) / (2 * Q_MAX) * (1 + 1e-9) + _HALF_ULP * np.maximum(np.abs(zmin), np.abs(zmax))
    return np.where(exact, 0.0, b)


def on_step_cells(heights, source_step: tuple[float, float] | None) -> np.ndarray | None:
    """Per cell of a grid (rows-1, cols-1), True where its four corner heights are on the source's step; None
    without a source step."""
    if source_step is None:
        return None
    step, offset = (float(v) for v in source_step)
    _, ok = _on_step(np.asarray(heights, dtype=np.float32), step, offset)
    return ok[:-1, :-1] & ok[:-1, 1:] & ok[1:, :-1] & ok[1:, 1:]
