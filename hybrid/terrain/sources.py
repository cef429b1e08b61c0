"""What terrain to load: a bundled or synthetic dataset name, or a file with its loader options, and its credit."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hybrid.errors import TerrabenchError
from hybrid.terrain.heightfield import HeightField
from hybrid.terrain.paths import path_problem
from hybrid.terrain.window import Crop

FILE_OPTIONS = ("spacing", "vertical_scale", "crs", "crop", "raw_shape", "raw_dtype")


@dataclass(frozen=True)
class TerrainSource:
    """A dataset name (``puget``, ``fbm``, ...) or a height-field file, with loader options and a credit line.

    ``spacing`` is metres (one number or (x, y)), ``vertical_scale`` metres per stored unit, ``crs`` a CRS
    override (any form pyproj reads), ``crop`` a window as stored in the file; they apply to files only.
    ``name`` labels the terrain in runs and reports (default: the dataset name or path).
    """

    dataset: str
    spacing: float | tuple[float, float] | None = None
    vertical_scale: float | None = None
    crs: str | None = None
    crop: Crop | None = None
    raw_shape: tuple[int, int] | None = None
    raw_dtype: str | None = None
    credit: str | None = None
    name: str | None = None

    @property
    def is_file(self) -> bool:
        """Whether the dataset is a file (not a bundled or synthetic name)."""
        from hybrid.terrain.datasets import NAMES

        return self.dataset not in NAMES

    @property
    def label(self) -> str:
        """The terrain's label in runs and reports: its name, else the dataset name or path."""
        return self.name or self.dataset

    def load(self, size: int | None = None, seed: int = 0) -> HeightField:
        """The HeightField; ``size`` (samples a side) and ``seed`` apply to synthetic data (size crops puget)."""
        from hybrid.terrain.datasets import NAMES, get_dataset
        from hybrid.terrain.loaders import load_terrain

        given = [k for k in FILE_OPTIONS if getattr(self, k) is not None]
        if not self.is_file:
            if given:
                raise TerrabenchError(
                    f"dataset {self.dataset!r} is bundled or synthetic; {', '.join(given)} apply to files only"
                )
            hf = get_dataset(self.dataset, size=size, seed=seed)
            if self.name is not None:
                hf.name = self.name
            return hf
        from hybrid.terrain.stored import is_store, open_store, store_remains

        if is_store(self.dataset) or store_remains(self.dataset):  # a tile store (damaged or not): stays on disk
            if given:
                raise TerrabenchError(
                    f"{self.dataset} is a tile store; {', '.join(given)} were applied when it was prepared"
                )
            return open_store(self.dataset)
        problem = path_problem(self.dataset)
        if problem is not None and (problem != "no such file" or Path(self.dataset).suffix):
            raise TerrabenchError(f"{self.dataset}: {problem}")
        if not Path(self.dataset).suffix:
            raise TerrabenchError(
                f"unknown dataset {self.dataset!r}; choose one of {', '.join(NAMES)}, a file path or "
                "a tile store (terrabench prepare)"
            )
        opts = {
            "spacing": self.spacing,
            "vertical_scale": self.vertical_scale,
            "crs": self.crs,
            "crop": self.crop,
            "name": self.name,
        }
        if self.raw_shape is not None or self.raw_dtype is not None:
            opts.update(shape=self.raw_shape, dtype=self.raw_dtype)
        return load_terrain(self.dataset, **opts)

    def credit_line(self) -> str | None:
        """Who to credit for the terrain: the given credit, a bundled dataset's, a note for an uncredited file,
        None for synthetic terrain."""
        from hybrid.terrain.datasets import CREDITS

        if self.credit:
            return f"{self.label}: {self.credit}"
        if self.dataset in CREDITS:
            return CREDITS[self.dataset]
        if self.is_file:
            return f"{self.label}: terrain from {Path(self.dataset).name}; no credit given (add `credit` to its entry)"
        return None
