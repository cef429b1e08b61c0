"""The frame target every method draws into: RGBA8 colour + 32-bit float reversed-Z depth, and its read-back."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hybrid.camera.view import View
from hybrid.errors import TerrabenchError
from hybrid.gl.context import depth32f_texture

SKY = (0.62, 0.74, 0.88, 0.0)


def check_png_path(path, what: str = "output") -> Path:
    """path as a Path if it ends in .png and its folder exists, else a TerrabenchError naming ``what``."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise TerrabenchError(f"{what} must end in .png, got {str(path)!r}")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise TerrabenchError(f"{what} folder {folder} does not exist")
    return path


@dataclass
class RenderResult:
    """One rendered frame: colour (H, W, 3 uint8, top row first), hit distance in metres (inf = no terrain).

    ``stats`` is the renderer's ``hybrid.contract.FrameStats``; ``maps`` holds optional per-pixel maps;
    ``plans`` the tiles drawn with their strategies (``hybrid.cost.planner.TilePlan``). A frame drawn
    without reading it back (``Renderer.render(read=False)``) has colour and distance None.
    """

    colour: np.ndarray | None
    distance: np.ndarray | None
    stats: Any = None
    maps: dict = field(default_factory=dict)
    plans: list = field(default_factory=list)

    def _read_back(self) -> tuple[np.ndarray, np.ndarray]:
        """(colour, distance) of a frame that was read back; TypeError for one drawn with ``read=False``."""
        if self.colour is None or self.distance is None:
            raise TypeError("the frame was drawn without reading it back (Renderer.render(read=False))")
        return self.colour, self.distance

    @property
    def mask(self) -> np.ndarray:
        """Coverage: True where a pixel shows terrain."""
        return np.isfinite(self._read_back()[1])

    def save(self, path) -> tuple[Path, Path]:
        """Write PATH.png and PATH.depth.npy (float32 metres, inf where no terrain); returns both paths."""
        from PIL import Image

        from hybrid.atomic import atomic_path

        colour, distance = self._read_back()
        path = check_png_path(path)
        depth_path = path.parent / (path.stem + ".depth.npy")
        with atomic_path(path) as png, atomic_path(depth_path) as npy:  # both land, or neither
            Image.fromarray(colour).save(png, format="PNG")
            with open(npy, "wb") as f:
                np.save(f, distance.astype(np.float32))
        return path, depth_path


class FrameTarget:
    """GPU colour + depth attachments of one viewport size; clear, bind and read back."""

    def __init__(self, ctx, width: int, height: int):
        self.ctx = ctx
        self.size = (int(width), int(height))
        self.colour = ctx.texture(self.size, 4)
        self.depth = depth32f_texture(ctx, self.size)
        self.fbo = ctx.framebuffer(color_attachments=[self.colour], depth_attachment=self.depth)

    @property
    def nbytes(self) -> int:
        """GPU bytes of the attachments (4 colour + 4 depth bytes a pixel)."""
        return self.size[0] * self.size[1] * 8

    def clear(self, colour=SKY) -> None:
        """Clear colour to the sky and depth to 0 (reversed Z: 0 is the far plane)."""
        self.fbo.clear(*colour, depth=0.0)

    def use(self) -> None:
        """Bind as the draw framebuffer with the project's depth state (GREATER, writes on)."""
        self.fbo.use()
        self.ctx.enable(self.ctx.DEPTH_TEST)
        self.ctx.depth_func = ">"

    def read_depth(self) -> np.ndarray:
        """Raw reversed-Z depth, (H, W) float32, top row first."""
        d = np.frombuffer(self.depth.read(alignment=4), dtype=np.float32).reshape(self.size[1], self.size[0])
        return d[::-1].copy()

    def read_colour(self) -> np.ndarray:
        """Colour as (H, W, 3) uint8, top row first."""
        c = np.frombuffer(self.fbo.read(components=4, alignment=1), dtype=np.uint8)
        return c.reshape(self.size[1], self.size[0], 4)[::-1, :, :3].copy()

    def read(self, view: View, stats=None) -> RenderResult:
        """Colour and per-pixel hit distance (metres, inf where empty) for the view that was drawn."""
        dist = view.distance_from_depth(self.read_depth())
        return RenderResult(self.read_colour(), dist, stats)

    def release(self) -> None:
        """Free the GPU attachments (binding the default framebuffer first if this one is bound: moderngl
        rebinds its last bound framebuffer when it makes the next one, and a deleted name is an error)."""
        if self.ctx.fbo is self.fbo:
            self.ctx.detect_framebuffer(0).use()
        for o in (self.fbo, self.colour, self.depth):
            o.release()
