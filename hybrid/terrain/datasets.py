"""Named terrains: the bundled Puget Sound model and seeded synthetic scenes, some made to break methods."""

from __future__ import annotations

from importlib import resources

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import HeightField

PUGET_SPACING = 160.0  # metres between samples
PUGET_SCALE = 0.1  # metres per 16-bit unit
PUGET_CREDIT = (
    "Puget Sound terrain: USGS data, made available by the University of Washington, "
    "via the Georgia Tech Large Geometric Models Archive."
)
CREDITS = {"puget": PUGET_CREDIT}  # credit lines of bundled data (synthetic terrain is made here)


def _data_path(name: str):
    return resources.files("hybrid.terrain") / "data" / name


def puget(with_texture: bool = True, size: int | None = None) -> HeightField:
    """The bundled Puget Sound model: 1025² samples, 160 m spacing, 0.1 m units, cell-centred texture.

    ``size`` (at most 1025) crops a size x size window around Mount Rainier at full resolution, for tests.
    """
    from hybrid.terrain.loaders import load_png16

    with (
        resources.as_file(_data_path("ps_height_1k.png")) as hp,
        resources.as_file(_data_path("ps_texture_1k.png")) as tp,
    ):
        hf = load_png16(
            hp,
            vertical_scale=PUGET_SCALE,
            spacing=PUGET_SPACING,
            texture_path=tp if with_texture else None,
            name="puget",
        )
    hf.notes.append(PUGET_CREDIT)
    if size is not None:
        hf = crop(hf, size, centre=(0.49, 0.78))
    return hf


def crop(hf: HeightField, size: int, centre=(0.5, 0.5)) -> HeightField:
    """A size x size window of hf around (row, col) fractions ``centre``, origin moved to keep world positions."""
    size = int(size)
    if not (2 <= size <= min(hf.rows, hf.cols)):
        raise TerrabenchError(f"crop size must lie in [2, {min(hf.rows, hf.cols)}], got {size}")
    i0 = int(np.clip(round(centre[0] * (hf.rows - 1) - size / 2), 0, hf.rows - size))
    j0 = int(np.clip(round(centre[1] * (hf.cols - 1) - size / 2), 0, hf.cols - size))
    tex = None if hf.texture is None else hf.texture[i0 : i0 + size - 1, j0 : j0 + size - 1]
    o = (hf.origin[0] + j0 * hf.spacing_x, hf.origin[1] + i0 * hf.spacing_y, hf.origin[2])
    return HeightField(
        hf.heights[i0 : i0 + size, j0 : j0 + size].copy(),
        (hf.spacing_x, hf.spacing_y),
        o,
        f"{hf.name}-{size}",
        tex,
        0,
        hf.source,
        list(hf.notes) + [f"window rows {i0}.. cols {j0}.. of {hf.rows}x{hf.cols}"],
        hf.source_step,
    )


BAND_SAMPLES = 1 << 20
"""Samples per row band of the synthetic generators: a band's three float64 work arrays take 24 MiB."""


def _lattices(n: int, rng: np.random.Generator, octaves: int) -> list[np.ndarray]:
    """Per octave, its random lattice interpolated along x to every column: (cells+1, n) float64, small."""
    out, cells = [], 4
    for _ in range(octaves):
        c = min(cells, n - 1)
        lattice = rng.uniform(-1.0, 1.0, size=(c + 1, c + 1))
        k, f = _cell_weights(n, c)
        fx = f[None, :]
        out.append(lattice[:, k] * (1 - fx) + lattice[:, k + 1] * fx)
        cells *= 2
    return out


def _cell_weights(n: int, cells: int) -> tuple[np.ndarray, np.ndarray]:
    """Lattice cell and smoothstep weight of each of n samples spread over ``cells`` lattice cells."""
    t = np.linspace(0.0, cells, n)
    k = np.minimum(np.floor(t).astype(int), cells - 1)
    f = t - k
    return k, f * f * (3 - 2 * f)


def _octave_band(xs: list[np.ndarray], n: int, rows: slice, ridged: bool) -> np.ndarray:
    """Rows ``rows`` of the octave sum (unnormalised, float64) of smooth value noise in [-1, 1]."""
    total: np.ndarray | None = None
    amp, norm = 1.0, 0.0
    for x in xs:
        k, f = _cell_weights(n, x.shape[0] - 1)
        k, fy = k[rows], f[rows][:, None]
        v = x[k]
        v *= 1 - fy
        w = x[k + 1]
        w *= fy
        v += w
        if ridged:
            np.abs(v, out=v)
            np.subtract(1.0, v, out=v)
            v *= v
        v *= amp
        total = v if total is None else np.add(total, v, out=total)
        norm += amp
        amp *= 0.5
    assert total is not None  # xs holds one lattice an octave, and there are octaves
    total /= norm
    return total


def _bands(n: int):
    """Row slices of an n x n grid, each of about BAND_SAMPLES samples."""
    step = max(1, BAND_SAMPLES // n)
    return [slice(i, min(i + step, n)) for i in range(0, n, step)]


def _octaves(n, rng, octaves, amplitude, ridged=False) -> np.ndarray:
    """Octaves of value noise scaled to 0..amplitude, float32, made in row bands (two passes when several:
    the range first, then the heights), so the peak is the float32 result and one band's float64 work."""
    xs = _lattices(n, rng, octaves)
    bands = _bands(n)
    if len(bands) == 1:
        h = _octave_band(xs, n, bands[0], ridged)
        return ((h - h.min()) / max(np.ptp(h), 1e-12) * amplitude).astype(np.float32)
    lo, hi = np.inf, -np.inf
    for rows in bands:
        b = _octave_band(xs, n, rows, ridged)
        lo, hi = min(lo, b.min()), max(hi, b.max())
    out = np.empty((n, n), np.float32)
    for rows in bands:
        out[rows] = (_octave_band(xs, n, rows, ridged) - lo) / max(hi - lo, 1e-12) * amplitude
    return out


def fbm(size=257, spacing=30.0, seed=0, amplitude=1500.0) -> HeightField:
    """Fractional Brownian motion terrain (value-noise octaves), heights 0..amplitude metres."""
    h = _octaves(size, np.random.default_rng(seed), 8, amplitude)
    return HeightField(h, spacing, name="fbm")


def ridged(size=257, spacing=30.0, seed=0, amplitude=2000.0) -> HeightField:
    """Ridged multifractal terrain (sharp crests), heights 0..amplitude metres."""
    h = _octaves(size, np.random.default_rng(seed), 8, amplitude, ridged=True)
    return HeightField(h, spacing, name="ridged")


def spike(size=257, spacing=30.0, seed=0, height=3000.0) -> HeightField:
    """Gentle terrain with one sample ``height`` metres above its neighbours (off any tile border)."""
    base = fbm(size, spacing, seed, amplitude=100.0).heights
    i, j = int(size * 0.55) | 1, int(size * 0.45) | 1
    base[i, j] += height
    hf = HeightField(base, spacing, name="spike")
    hf.notes.append(f"spike at row {i}, column {j}")
    return hf


def cliff(size=257, spacing=30.0, seed=0, height=800.0) -> HeightField:
    """A vertical step of ``height`` metres between two sample columns, with mild noise on both sides."""
    base = fbm(size, spacing, seed, amplitude=60.0).heights
    j = int(size * 0.6) | 1
    base[:, j:] += height
    hf = HeightField(base, spacing, name="cliff")
    hf.notes.append(f"step between columns {j - 1} and {j}")
    return hf


def staircase(size=257, spacing=30.0, seed=0, step_cells=12, rise=60.0) -> HeightField:
    """Terraces: height rises by ``rise`` metres every ``step_cells`` samples east and north."""
    j = np.arange(size) // step_cells
    h = np.empty((size, size), np.float32)
    for rows in _bands(size):
        h[rows] = (j[None, :] + np.arange(rows.start, rows.stop)[:, None] // (2 * step_cells)) * rise
    return HeightField(h, spacing, name="staircase")


def flat(size=257, spacing=30.0, seed=0) -> HeightField:
    """All heights zero: a height range of exactly 0."""
    return HeightField(np.zeros((size, size), np.float32), spacing, name="flat")


def sine_ridges(size=257, spacing=30.0, seed=0, amplitude=400.0, period_cells=16) -> HeightField:
    """Sine ridges running exactly along the grid's x axis and y axis (crest lines on sample rows/columns)."""
    t = np.arange(size, dtype=np.float64)
    east = amplitude * 0.5 * (np.cos(2 * np.pi * t / period_cells) + 1) * 0.7
    north = amplitude * 0.5 * (np.cos(2 * np.pi * t / (2 * period_cells)) + 1) * 0.3
    h = np.empty((size, size), np.float32)
    for rows in _bands(size):
        h[rows] = east[None, :] + north[rows, None]
    return HeightField(h, spacing, name="ridges")


MAX_SYNTHETIC_SIZE = 16385
"""Largest synthetic terrain made in memory, samples a side; larger ones are prepared out of core."""

PEAK_BASE_BYTES = 192 << 20
PEAK_BYTES_PER_SAMPLE = 5
"""Peak memory of a synthetic terrain and its tile pyramid (`terrabench info --dataset fbm --no-gl`): about
PEAK_BASE_BYTES (the interpreter and libraries) plus PEAK_BYTES_PER_SAMPLE a sample, 4 of them the float32
heights. Measured peak RSS on the 2-core llvmpipe machine: 148 MiB at 1025², 167 MiB at 2049², 235 MiB at
4097², 463 MiB at 8193² and 1.35 GiB at 16385² (151 s)."""


def synthetic_peak_bytes(size: int) -> int:
    """Estimated peak memory (bytes) of making a size x size synthetic terrain and its tile pyramid."""
    return PEAK_BASE_BYTES + PEAK_BYTES_PER_SAMPLE * int(size) ** 2


SYNTHETIC = {
    "fbm": fbm,
    "ridged": ridged,
    "spike": spike,
    "cliff": cliff,
    "staircase": staircase,
    "flat": flat,
    "ridges": sine_ridges,
}
NAMES = ("puget",) + tuple(SYNTHETIC)


def get_dataset(name: str, size: int | None = None, seed: int = 0) -> HeightField:
    """A bundled (``puget``) or synthetic terrain by name; ``size`` samples per side for synthetic ones."""
    if name == "puget":
        return puget(size=size)
    if name not in SYNTHETIC:
        raise TerrabenchError(f"unknown dataset {name!r}; choose one of {', '.join(NAMES)} or give a file")
    if size is not None and not (3 <= int(size) <= MAX_SYNTHETIC_SIZE):
        top = MAX_SYNTHETIC_SIZE
        raise TerrabenchError(
            f"dataset size must lie in [3, {top}] samples, got {size} (a {top}² synthetic terrain takes about "
            f"{synthetic_peak_bytes(top) / 2**30:.1f} GiB; for larger ones build a tile store out of core: "
            f"terrabench prepare --synthetic SIZE --out STORE)"
        )
    return SYNTHETIC[name](size=int(size or 257), seed=int(seed))
