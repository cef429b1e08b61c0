"""Draw options of the raster strategies, checked: the per-tile meshes' and the tilelets'."""

from __future__ import annotations

from dataclasses import dataclass
from typing import get_args

import numpy as np

from hybrid.contract import DEFAULT_FULL_RES, FULL_RES, DrawOptions, FullRes, check_flags
from hybrid.errors import TerrabenchError

from .shading import RasterMode

RASTER_MODES: tuple[str, ...] = get_args(RasterMode)


def _check_mode(mode) -> None:
    if mode is not None and mode not in RASTER_MODES:
        raise TerrabenchError(f"raster mode must be one of {', '.join(RASTER_MODES)} (or None), got {mode!r}")


@dataclass(frozen=True)
class MeshOptions(DrawOptions):
    """How the per-tile meshes (``fullres``, ``tin``) are drawn.

    mode: shading mode (None: 'texture' when the terrain has one, else 'shaded').
    wireframe: draw the triangles' edges only.
    seam_skirts: hang skirts from tile sides whose neighbour differs (not in wireframe).
    """

    mode: RasterMode | None = None
    wireframe: bool = False
    seam_skirts: bool = True

    def __post_init__(self):
        _check_mode(self.mode)
        check_flags(self, ("wireframe", "seam_skirts"))


@dataclass(frozen=True)
class TileletOptions(DrawOptions):
    """How the restricted-quadtree tilelets (``raster``, ``raster_gs``) are selected and drawn.

    mode, wireframe: as ``MeshOptions``.
    morph: geomorph vertices between levels; stitching: close cracks to coarser neighbours; lean: drop the edge
      midpoints that no finer neighbour or near split needs; culling: skip tilelets outside the frustum.
    leaf_tau: screen-space error (px) the leaves are selected at, instead of the frame's tau (None: the frame's).
    full_res: the full-resolution leaves' rule (``hybrid.contract.FULL_RES``).
    lod_eye: world metres (3,) the leaves are selected as seen from (a held level of detail; None: the view's eye).
    """

    mode: RasterMode | None = None
    wireframe: bool = False
    morph: bool = True
    stitching: bool = True
    lean: bool = True
    culling: bool = True
    leaf_tau: float | None = None
    full_res: FullRes = DEFAULT_FULL_RES
    lod_eye: np.ndarray | tuple | None = None

    def __post_init__(self):
        _check_mode(self.mode)
        check_flags(self, ("wireframe", "morph", "stitching", "lean", "culling"))
        if self.leaf_tau is not None and (
            isinstance(self.leaf_tau, bool) or not isinstance(self.leaf_tau, (int, float)) or not self.leaf_tau > 0
        ):
            raise TerrabenchError(f"leaf_tau must be None or a number of pixels > 0, got {self.leaf_tau!r}")
        if self.full_res not in FULL_RES:
            raise TerrabenchError(f"full_res must be one of {', '.join(FULL_RES)}, got {self.full_res!r}")
        if self.lod_eye is not None and not (
            np.shape(self.lod_eye) == (3,) and np.all(np.isfinite(np.asarray(self.lod_eye, dtype=np.float64)))
        ):
            raise TerrabenchError(f"lod_eye must be None or three finite world metres, got {self.lod_eye!r}")
