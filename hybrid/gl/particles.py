"""Particles on a changing terrain (the seed paper's bouncing balls): a compute pass over the GPU heights, sprites.

``ParticleSystem`` keeps N particles' positions and velocities in shader storage buffers (metres and metres a
second, relative to the terrain's origin: x east, y north, z up) and steps them on the GPU with gravity,
restitution and friction, in at most ``MAX_SUBSTEPS`` sub-steps a frame. Each particle reads the same R32F heights
texture the brush pass edits (``hybrid.gl.brush.GpuHeights``; a grid within the GL's size limit, held in one
texture), through the reference's triangles or the bilinear
patch, and is pushed above the surface on contact: a raise lifts resting particles, a crater lets them fall. The
extent's walls mirror particles back, so they stay on the terrain. ``draw`` puts them as round point sprites into
a frame target, depth-tested against the terrain already drawn there; ``timed_step`` and ``timed_draw`` time each
pass apart (wall clock around glFinish, a GL timer query where valid: ``hybrid.gl.timing``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hybrid.camera.view import View
from hybrid.errors import TerrabenchError
from hybrid.gl.brush import GpuHeights
from hybrid.gl.context import gl_bytes
from hybrid.gl.programs import compute_shader, program, set_uniform
from hybrid.gl.target import FrameTarget
from hybrid.gl.timing import timed

MAX_PARTICLES = 1 << 22  # 64 MiB of positions, velocities and spawn points
MAX_SUBSTEPS = 64  # the compute pass's loop cap
GROUP = 64  # the pass's work group size
RECONSTRUCTIONS = ("triangles", "bilinear")


@dataclass(frozen=True)
class ParticleParams:
    """How particles spawn and move: count, seconds a frame (``dt``) split into ``substeps``, gravity (m/s²),
    restitution and friction (shares, [0, 1]), clearance (m above the surface), drop (m above the surface at
    spawn), sprite size (pixels), colour (RGB 0..1), the surface reconstruction and the spawn seed."""

    count: int = 4096
    dt: float = 1.0 / 30.0
    substeps: int = 4
    gravity: float = 9.81
    restitution: float = 0.5
    friction: float = 0.2
    clearance: float = 0.5
    drop: float = 20.0
    point_px: float = 3.0
    colour: tuple[float, float, float] = (0.3, 0.85, 1.0)
    reconstruction: str = "triangles"
    seed: int = 0


def check_particles(p: ParticleParams) -> ParticleParams:
    """The parameters if every value is in range, else a TerrabenchError naming the first that is not."""

    def number(name, lo, hi):
        v = getattr(p, name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
            raise TerrabenchError(f"particle {name} must be a finite number in [{lo:g}, {hi:g}], got {v!r}")

    for name, lo, hi in (("count", 0, MAX_PARTICLES), ("substeps", 1, MAX_SUBSTEPS), ("seed", 0, 2**32 - 1)):
        v = getattr(p, name)
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise TerrabenchError(f"particle {name} must be an integer in [{lo}, {hi}], got {v!r}")
    for name, low, high in (
        ("dt", 1e-6, 10.0),
        ("gravity", 0.0, 1e3),
        ("restitution", 0.0, 1.0),
        ("friction", 0.0, 1.0),
        ("clearance", 0.0, 1e4),
        ("drop", 0.0, 1e5),
        ("point_px", 1.0, 64.0),
    ):
        number(name, low, high)
    if p.reconstruction not in RECONSTRUCTIONS:
        raise TerrabenchError(
            f"particle reconstruction must be one of {', '.join(RECONSTRUCTIONS)}, got {p.reconstruction!r}"
        )
    return p


@dataclass(frozen=True)
class PassTime:
    """One timed pass: wall ms around glFinish, and GPU ms from a timer query (None where the GL has none)."""

    wall_ms: float
    gpu_ms: float | None


def spawn_points(heights: GpuHeights, p: ParticleParams) -> np.ndarray:
    """float32 (count, 4) spawn positions (metres, relative to the terrain origin): uniform over the extent, ``drop``
    metres above the surface the particles read (its reconstruction, from the CPU copy of the heights)."""
    hf = heights.hf
    rng = np.random.default_rng(p.seed)
    w, d = hf.extent
    xy = rng.uniform(0.0, 1.0, (p.count, 2)) * np.array([w, d])
    i, j = xy[:, 1] / hf.spacing_y, xy[:, 0] / hf.spacing_x
    z = hf.sample_bilinear(i, j) if p.reconstruction == "bilinear" else hf.sample_triangles(i, j)
    out = np.zeros((p.count, 4), np.float32)
    out[:, :2], out[:, 2] = xy, z + p.clearance + p.drop
    return out


class ParticleSystem:
    """GPU state of N particles on one terrain's GPU heights: their buffers, the step and draw programs."""

    def __init__(self, ctx, heights: GpuHeights, params: ParticleParams):
        self.ctx, self.heights, self.params = ctx, heights, check_particles(params)
        self.texture = heights.texture  # the one texture of the heights (a grid in blocks is refused by name)
        self.step_prog = compute_shader(
            ctx,
            "hybrid.gl",
            "particles.comp.glsl",
            {"MAX_SUBSTEPS": MAX_SUBSTEPS, "BILINEAR": int(params.reconstruction == "bilinear")},
        )
        self.draw_prog = program(ctx, "hybrid.gl", "particles.vert.glsl", "particles.frag.glsl")
        self.vao = ctx.vertex_array(self.draw_prog, [])
        self.buffers: list = []
        self.frames = 0
        self.reset()

    @property
    def count(self) -> int:
        """How many particles."""
        return self.params.count

    def reset(self) -> None:
        """Every particle back at its spawn point, at rest."""
        for b in self.buffers:
            b.release()
        self.buffers, self.frames = [], 0
        if self.count:
            home = spawn_points(self.heights, self.params)
            zeros = np.zeros_like(home)
            self.buffers = [self.ctx.buffer(a.tobytes()) for a in (home, zeros, home)]

    def step(self) -> None:
        """Advance every particle by one frame (``dt`` seconds in ``substeps`` sub-steps) on the heights as they are."""
        if not self.count:
            return
        p, hf, prog = self.params, self.heights.hf, self.step_prog
        self.texture.bind_to_image(0, read=True, write=False)
        for unit, b in enumerate(self.buffers):
            b.bind_to_storage_buffer(unit)
        values: dict = {
            "count": p.count,
            "grid": (hf.cols, hf.rows),
            "spacing": (hf.spacing_x, hf.spacing_y),
            "dt": p.dt / p.substeps,
            "substeps": p.substeps,
            "gravity": p.gravity,
            "restitution": p.restitution,
            "friction": p.friction,
            "clearance": p.clearance,
        }
        for name, v in values.items():
            set_uniform(prog, name, v)
        prog.run(-(-p.count // GROUP), 1, 1)
        self.ctx.memory_barrier()
        self.frames += 1

    def draw(self, target: FrameTarget, view: View) -> None:
        """Draw the particles as round sprites into target (the view's size), depth-tested against what it holds."""
        if not self.count:
            return
        prog = self.draw_prog
        set_uniform(prog, "origin_rel", tuple((np.array(self.heights.hf.origin) - view.eye).astype(np.float32)))
        set_uniform(prog, "point_px", float(self.params.point_px))
        set_uniform(prog, "colour", tuple(float(c) for c in self.params.colour))
        u = prog.get("view_proj_rel", None)
        if u is not None:
            u.write(view.view_proj_rel.T.astype(np.float32).tobytes())
        target.use()
        self.ctx.enable(self.ctx.PROGRAM_POINT_SIZE)
        self.buffers[0].bind_to_storage_buffer(0)
        self.vao.render(self.ctx.POINTS, vertices=self.count)
        self.ctx.disable(self.ctx.PROGRAM_POINT_SIZE)

    def timed_step(self) -> PassTime:
        """``step`` timed: wall ms around glFinish, GPU ms where timer queries are valid."""
        _, wall, gpu, _ = timed(self.ctx, self.step)
        return PassTime(wall, gpu)

    def timed_draw(self, target: FrameTarget, view: View) -> PassTime:
        """``draw`` timed as ``timed_step``."""
        _, wall, gpu, _ = timed(self.ctx, lambda: self.draw(target, view))
        return PassTime(wall, gpu)

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """(positions, velocities): float32 (count, 3) metres and metres a second, relative to the terrain origin."""
        if not self.count:
            return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)
        pos, vel = (np.frombuffer(b.read(), np.float32).reshape(-1, 4)[:, :3].copy() for b in self.buffers[:2])
        return pos, vel

    def world_positions(self) -> np.ndarray:
        """float64 (count, 3) world positions (metres, the terrain's frame: origin added)."""
        return self.read()[0].astype(np.float64) + np.asarray(self.heights.hf.origin, np.float64)

    @property
    def nbytes(self) -> int:
        """GPU bytes of the particle buffers, as the driver reports them."""
        return gl_bytes(*self.buffers)

    def release(self) -> None:
        """Free the buffers and programs."""
        for o in (*self.buffers, self.vao, self.step_prog, self.draw_prog):
            o.release()
        self.buffers = []

    def __enter__(self) -> ParticleSystem:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def surface_below(heights: GpuHeights, xy: np.ndarray, reconstruction: str = "triangles") -> np.ndarray:
    """float64 surface height (metres, relative to the origin z) below local (x, y) metres, read from the GPU
    heights themselves (the texels the particles read), through the given reconstruction."""
    hf = heights.hf
    grid = heights.read().astype(np.float64)
    view = type(hf)(grid, hf.spacing, hf.origin, hf.name)
    i, j = xy[:, 1] / hf.spacing_y, xy[:, 0] / hf.spacing_x
    return view.sample_bilinear(i, j) if reconstruction == "bilinear" else view.sample_triangles(i, j)
