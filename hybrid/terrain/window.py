"""A crop window of a grid file, in the file's own stored row order (row 0 is the first row stored)."""

from __future__ import annotations

from dataclasses import dataclass

from hybrid.errors import TerrabenchError, TerrainLoadError


@dataclass(frozen=True)
class Crop:
    """First row, first column and size (rows, cols) in samples of a window, rows as stored in the file.

    For north-up files (GeoTIFF, PNG, SRTM, raw) row 0 is the north edge, as GDAL and image viewers count;
    for ``.npy``/``.npz`` (stored south-up) row 0 is the south edge.
    """

    row: int
    col: int
    rows: int
    cols: int

    def __post_init__(self):
        for key in ("row", "col", "rows", "cols"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int):
                raise TerrabenchError(f"crop {key} must be an integer number of samples, got {v!r}")
        if self.row < 0 or self.col < 0:
            raise TerrabenchError(f"crop row and col must be >= 0, got row {self.row}, col {self.col}")
        if self.rows < 2 or self.cols < 2:
            raise TerrabenchError(f"a crop needs at least 2x2 samples, got rows {self.rows}, cols {self.cols}")

    @classmethod
    def parse(cls, text: str, option: str = "--crop") -> Crop:
        """A crop from 'ROW,COL,ROWS,COLS' (samples)."""
        try:
            row, col, rows, cols = (int(s) for s in str(text).split(","))
        except ValueError:
            raise TerrabenchError(f"{option} must be ROW,COL,ROWS,COLS (integers, samples), got {text!r}") from None
        return cls(row, col, rows, cols)

    def check(self, shape: tuple[int, int], where: str) -> None:
        """Refuse a window that does not lie inside a grid of shape (rows, cols)."""
        if self.row + self.rows > shape[0] or self.col + self.cols > shape[1]:
            raise TerrainLoadError(
                f"{where}: crop rows {self.row}..{self.row + self.rows - 1}, cols "
                f"{self.col}..{self.col + self.cols - 1} does not fit the {shape[0]}x{shape[1]} "
                "grid (rows x cols)"
            )

    def slices(self) -> tuple[slice, slice]:
        """Row and column slices of the window."""
        return slice(self.row, self.row + self.rows), slice(self.col, self.col + self.cols)

    def describe(self) -> str:
        """The window in words, for notes."""
        return f"rows {self.row}..{self.row + self.rows - 1}, cols {self.col}..{self.col + self.cols - 1} as stored"
