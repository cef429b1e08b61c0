"""Named terrains: the bundled Puget Sound model and seeded synthetic scenes, some made to break methods."""
from __future__ import annotations

from importlib import resources

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import HeightField

PUGET_SPACING = 160.0     # metres between samples
PUGET_SCALE = 0.1         # metres per 16-bit unit
PUGET_CREDIT = ("Puget Sound terrain: USGS data, made available by the University of Washington, "
                "via the Georgia Tech Large Geometric Models Archive.")
CREDITS = {"puget": PUGET_CREDIT}   # credit lines of bundled data (synthetic terrain is made here)


def _data_path(name: str):
    return resources.files("hybrid.terrain") / "data" / name


def puget(with_texture: bool = True, size: int | None = None) -> HeightField:
    """The bundled Puget Sound model: 1025² samples, 160 m spacing, 0.1 m units, cell-centred texture.

    ``size`` (at most 1025) crops a size x size window around Mount Rainier at full resolution, for tests.
    """
    from hybrid.terrain.loaders import load_png16
    with resources.as_file(_data_path("ps_height_1k.png")) as hp, resources.as_file(_data_path("ps_texture_1k.png")) as tp:
        hf = load_png16(hp, vertical_scale=PUGET_SCALE, spacing=PUGET_SPACING,
                        texture_path=tp if with_texture else None, name="puget")
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
    tex = None if hf.texture is None else hf.texture[i0:i0 + size - 1, j0:j0 + size - 1]
    o = (hf.origin[0] + j0 * hf.spacing_x, hf.origin[1] + i0 * hf.spacing_y, hf.origin[2])
    return HeightField(hf.heights[i0:i0 + size, j0:j0 + size].copy(), (hf.spacing_x, hf.spacing_y), o,
                       f"{hf.name}-{size}", tex, 0, hf.source, list(hf.notes) + [f"window rows {i0}.. cols {j0}.. of {hf.rows}x{hf.cols}"],
                       hf.source_step)


def _value_noise(n: int, cells: int, rng: np.random.Generator) -> np.ndarray:
    """Smooth value noise in [-1, 1] on an n x n grid from a (cells+1)² random lattice."""
    lattice = rng.uniform(-1.0, 1.0, size=(cells + 1, cells + 1))
    t = np.linspace(0.0, cells, n)
    k = np.minimum(np.floor(t).astype(int), cells - 1)
    f = t - k
    f = f * f * (3 - 2 * f)
    a = lattice[np.ix_(k, k)]
    b = lattice[np.ix_(k, k + 1)]
    c = lattice[np.ix_(k + 1, k)]
    d = lattice[np.ix_(k + 1, k + 1)]
    fx, fy = f[None, :], f[:, None]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


def _octaves(n, rng, octaves, ridged=False):
    total = np.zeros((n, n))
    amp, cells, norm = 1.0, 4, 0.0
    for _ in range(octaves):
        cells_o = min(cells, n - 1)
        v = _value_noise(n, cells_o, rng)
        if ridged:
            v = 1.0 - np.abs(v)
            v = v * v
        total += amp * v
        norm += amp
        amp *= 0.5
        cells *= 2
    return total / norm


def fbm(size=257, spacing=30.0, seed=0, amplitude=1500.0) -> HeightField:
    """Fractional Brownian motion terrain (value-noise octaves), heights 0..amplitude metres."""
    rng = np.random.default_rng(seed)
    h = _octaves(size, rng, 8)
    h = (h - h.min()) / max(np.ptp(h), 1e-12) * amplitude
    return HeightField(h.astype(np.float32), spacing, name="fbm")


def ridged(size=257, spacing=30.0, seed=0, amplitude=2000.0) -> HeightField:
    """Ridged multifractal terrain (sharp crests), heights 0..amplitude metres."""
    rng = np.random.default_rng(seed)
    h = _octaves(size, rng, 8, ridged=True)
    h = (h - h.min()) / max(np.ptp(h), 1e-12) * amplitude
    return HeightField(h.astype(np.float32), spacing, name="ridged")


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
    i, j = np.mgrid[0:size, 0:size]
    h = (j // step_cells + i // (2 * step_cells)) * rise
    return HeightField(h.astype(np.float32), spacing, name="staircase")


def flat(size=257, spacing=30.0, seed=0) -> HeightField:
    """All heights zero: a height range of exactly 0."""
    return HeightField(np.zeros((size, size), np.float32), spacing, name="flat")


def sine_ridges(size=257, spacing=30.0, seed=0, amplitude=400.0, period_cells=16) -> HeightField:
    """Sine ridges running exactly along the grid's x axis and y axis (crest lines on sample rows/columns)."""
    i, j = np.mgrid[0:size, 0:size].astype(np.float64)
    h = amplitude * 0.5 * (np.cos(2 * np.pi * j / period_cells) + 1) * 0.7 \
        + amplitude * 0.5 * (np.cos(2 * np.pi * i / (2 * period_cells)) + 1) * 0.3
    return HeightField(h.astype(np.float32), spacing, name="ridges")


SYNTHETIC = {"fbm": fbm, "ridged": ridged, "spike": spike, "cliff": cliff, "staircase": staircase,
             "flat": flat, "ridges": sine_ridges}
NAMES = ("puget",) + tuple(SYNTHETIC)


def get_dataset(name: str, size: int | None = None, seed: int = 0) -> HeightField:
    """A bundled (``puget``) or synthetic terrain by name; ``size`` samples per side for synthetic ones."""
    if name == "puget":
        return puget(size=size)
    if name not in SYNTHETIC:
        raise TerrabenchError(f"unknown dataset {name!r}; choose one of {', '.join(NAMES)} or give a file")
    if size is not None and not (3 <= int(size) <= 16385):
        raise TerrabenchError(f"dataset size must lie in [3, 16385] samples, got {size}")
    return SYNTHETIC[name](size=int(size or 257), seed=int(seed))
