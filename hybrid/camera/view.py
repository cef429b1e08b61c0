"""Views: camera placement, float64 view/projection matrices, frusta, pixel rays and depth-to-distance.

Camera frame: right-handed, looking down -z of eye space, +y up on screen. Projection: reversed Z with
clip depth in [0, 1] (near plane -> 1, far plane -> 0; see hybrid.gl.context). What goes to the GPU is
relative to the eye: ``view_proj_rel`` maps (world - eye) to clip space, so terrain far from the world
origin loses no float32 precision. Images are stored top row first; pixel (r, c) has its centre at
(c + 0.5, r + 0.5) from the top-left corner.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hybrid.errors import TerrabenchError, check_positive, check_range

MAX_DEPTH_RATIO = 1e12  # far / near at most: beyond it the far plane's normal underflows
MAX_VIEWPORT = 16384
MAX_COORDINATE = 1.0e9  # metres: |eye|, |target| and terrain origins stay within (float64 ~1e-7 m steps)
DEPTH_CHUNK_PIXELS = 1 << 22  # pixels converted at a time from depth to distance (bounded temporaries)


def parse_size(text, what: str = "size") -> tuple[int, int]:
    """(width, height) in pixels from 'WIDTHxHEIGHT', each in [1, MAX_VIEWPORT], else an error naming ``what``."""
    try:
        w, h = (int(x) for x in str(text).lower().split("x"))
    except ValueError:
        w = h = 0
    if not (1 <= w <= MAX_VIEWPORT and 1 <= h <= MAX_VIEWPORT):
        raise TerrabenchError(
            f"{what} must be WIDTHxHEIGHT in pixels with width and height in [1, {MAX_VIEWPORT}], got {text!r}"
        )
    return w, h


def _vec3(name, v) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise TerrabenchError(f"{name} must be 3 numbers (x, y, z), got {v!r}") from None
    if not np.all(np.isfinite(a)):
        raise TerrabenchError(f"{name} must be finite, got {v!r}")
    return a


@dataclass(frozen=True)
class View:
    """A pinhole camera: eye and target in world metres, vertical FOV in degrees, viewport in pixels."""

    eye: np.ndarray
    target: np.ndarray
    fov_y: float = 60.0
    width: int = 640
    height: int = 360
    near: float = 1.0
    far: float = 1.0e6
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    def __post_init__(self):
        object.__setattr__(self, "eye", _vec3("eye", self.eye))
        object.__setattr__(self, "target", _vec3("target", self.target))
        object.__setattr__(self, "up", _vec3("up", self.up))
        scale = float(np.abs(self.up).max())
        if scale == 0.0:
            raise TerrabenchError("up must be a non-zero vector, got (0, 0, 0)")
        object.__setattr__(self, "up", self.up / scale)  # only its direction matters; no overflow
        for name in ("eye", "target"):
            far_off = float(np.abs(getattr(self, name)).max())
            if far_off > MAX_COORDINATE:
                raise TerrabenchError(
                    f"{name} coordinate {far_off:g} m is beyond the world limit of "
                    f"±{MAX_COORDINATE:g} m (float64 keeps sub-millimetre steps only within it)"
                )
        check_range("fov_y (degrees)", self.fov_y, 0.0, 180.0)
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not (1 <= v <= MAX_VIEWPORT):
                raise TerrabenchError(f"viewport {name} must be an integer in [1, {MAX_VIEWPORT}] pixels, got {v!r}")
            object.__setattr__(self, name, int(v))
        check_positive("near (metres)", self.near)
        check_positive("far (metres)", self.far)
        if not self.far > self.near:
            raise TerrabenchError(f"far ({self.far}) must be greater than near ({self.near})")
        if self.far > MAX_DEPTH_RATIO * self.near:
            raise TerrabenchError(
                f"far / near is {self.far / self.near:.3g}, above {MAX_DEPTH_RATIO:g}: the frustum's "
                f"planes and a depth buffer cannot resolve that; raise near ({self.near}) or lower far"
            )
        d = self.target - self.eye
        if np.linalg.norm(d) <= 1e-9 * max(1.0, float(np.linalg.norm(self.eye))):
            raise TerrabenchError("target must differ from eye")
        object.__setattr__(self, "fov_y", float(self.fov_y))
        object.__setattr__(self, "near", float(self.near))
        object.__setattr__(self, "far", float(self.far))

    # --- camera frame -------------------------------------------------------------------------
    @property
    def forward(self) -> np.ndarray:
        """Unit viewing direction in world space."""
        d = self.target - self.eye
        return d / np.linalg.norm(d)

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Right, up and back unit vectors of the camera in world space (rows of the view rotation).

        When the view direction is (nearly) parallel to ``up``, world north (0, 1, 0) is used as up.
        """
        f = self.forward
        up = self.up / np.linalg.norm(self.up)
        if abs(np.dot(f, up)) > 1.0 - 1e-9:
            up = np.array([0.0, 1.0, 0.0]) if abs(f[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        r = np.cross(f, up)
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        return r, u, -f

    @property
    def aspect(self) -> float:
        """Viewport width / height."""
        return self.width / self.height

    @property
    def tan_half_fov(self) -> float:
        """tan(fov_y / 2)."""
        return float(np.tan(np.radians(self.fov_y) * 0.5))

    @property
    def pixels_per_radian(self) -> float:
        """Screen-space scale K: a length L metres at distance d metres spans about K*L/d pixels."""
        return self.height / (2.0 * self.tan_half_fov)

    def rotation(self) -> np.ndarray:
        """3x3 world-to-eye rotation (float64); computed once per view (views are immutable)."""
        rot = self.__dict__.get("_rotation")
        if rot is None:
            rot = np.stack(self.basis())
            rot.setflags(write=False)
            self.__dict__["_rotation"] = rot
        return rot

    def view_matrix(self) -> np.ndarray:
        """4x4 world-to-eye matrix in float64 (absolute world coordinates)."""
        m = np.eye(4)
        R = self.rotation()
        m[:3, :3] = R
        m[:3, 3] = -R @ self.eye
        return m

    def projection(self) -> np.ndarray:
        """4x4 reversed-Z perspective projection to clip space with depth in [0, 1] (float64)."""
        n, f = self.near, self.far
        t = 1.0 / self.tan_half_fov
        p = np.zeros((4, 4))
        p[0, 0] = t / self.aspect
        p[1, 1] = t
        p[2, 2] = n / (f - n)
        p[2, 3] = n * f / (f - n)
        p[3, 2] = -1.0
        return p

    @property
    def view_proj_rel(self) -> np.ndarray:
        """4x4 float64 matrix from eye-relative world coordinates (world - eye) to clip space; computed once per
        view (read-only)."""
        vp = self.__dict__.get("_view_proj_rel")
        if vp is None:
            m = np.eye(4)
            m[:3, :3] = self.rotation()
            vp = self.projection() @ m
            vp.setflags(write=False)
            self.__dict__["_view_proj_rel"] = vp
        return vp

    def view_proj(self) -> np.ndarray:
        """4x4 float64 matrix from absolute world coordinates to clip space."""
        return self.projection() @ self.view_matrix()

    def frustum_planes_rel(self) -> np.ndarray:
        """6x4 planes (a, b, c, d), a*x+b*y+c*z+d >= 0 inside, for eye-relative world points; unit normals.

        Order: left, right, bottom, top, near, far. Computed once per view (read-only).
        """
        planes = self.__dict__.get("_planes_rel")
        if planes is None:
            m = self.view_proj_rel
            planes = np.array([m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[3] - m[2], m[2]])
            planes /= np.linalg.norm(planes[:, :3], axis=1, keepdims=True)
            planes.setflags(write=False)
            self.__dict__["_planes_rel"] = planes
        return planes

    # --- rays and depth -----------------------------------------------------------------------
    def pixel_dirs_eye(self, rows=None, cols=None) -> np.ndarray:
        """Eye-space directions (x, y, -1) through pixel centres; full image (H, W, 3) if rows/cols None."""
        if rows is None:
            rows, cols = np.mgrid[0 : self.height, 0 : self.width]
        rows = np.asarray(rows, dtype=np.float64)
        cols = np.asarray(cols, dtype=np.float64)
        ndc_x = (cols + 0.5) / self.width * 2.0 - 1.0
        ndc_y = 1.0 - (rows + 0.5) / self.height * 2.0
        t = self.tan_half_fov
        return np.stack([ndc_x * t * self.aspect, ndc_y * t, -np.ones_like(ndc_x)], axis=-1)

    def pixel_rays(self, rows=None, cols=None) -> np.ndarray:
        """Unit world-space ray directions (float64) through pixel centres, shape (..., 3)."""
        d = self.pixel_dirs_eye(rows, cols) @ self.rotation()
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def distance_from_depth(self, depth: np.ndarray) -> np.ndarray:
        """Eye-to-surface distance in metres from a reversed-Z depth image (top row first); inf where 0."""
        depth = np.asarray(depth)
        if depth.shape != (self.height, self.width):
            raise TerrabenchError(
                f"depth image of shape {depth.shape} does not match the view's {self.height}x{self.width} pixels"
            )
        n, f = self.near, self.far
        a, b = n / (f - n), n * f / (f - n)
        t = self.tan_half_fov
        # the eye-space ray length through a pixel is separable in column and row: sqrt(1 + x² + y²)
        x2 = (((np.arange(self.width) + 0.5) / self.width * 2.0 - 1.0) * t * self.aspect) ** 2
        y2 = ((1.0 - (np.arange(self.height) + 0.5) / self.height * 2.0) * t) ** 2
        out = np.empty(depth.shape, np.float32)
        step = max(1, DEPTH_CHUNK_PIXELS // max(self.width, 1))
        for r in range(0, self.height, step):  # bounded float64 temporaries on huge images
            d = depth[r : r + step].astype(np.float64)
            with np.errstate(divide="ignore", invalid="ignore"):
                dist = b / (a + d) * np.sqrt(1.0 + x2[None, :] + y2[r : r + step, None])
            out[r : r + step] = np.where(d > 0.0, dist, np.inf)
        return out

    def project(self, points: np.ndarray) -> np.ndarray:
        """Screen position (col, row, depth) of world points (float64), rows from the top; depth reversed-Z."""
        p = np.asarray(points, dtype=np.float64) - self.eye
        h = np.concatenate([p, np.ones(p.shape[:-1] + (1,))], axis=-1) @ self.view_proj_rel.T
        ndc = h[..., :3] / h[..., 3:4]
        col = (ndc[..., 0] + 1) * 0.5 * self.width
        row = (1 - ndc[..., 1]) * 0.5 * self.height
        return np.stack([col, row, ndc[..., 2]], axis=-1)

    def with_size(self, width: int, height: int) -> View:
        """The same camera with another viewport size."""
        return View(self.eye, self.target, self.fov_y, width, height, self.near, self.far, self.up)

    def moved(self, offset) -> View:
        """The same camera translated by a world offset (metres)."""
        o = _vec3("offset", offset)
        return View(self.eye + o, self.target + o, self.fov_y, self.width, self.height, self.near, self.far, self.up)


STRIP_ASPECT = 8.0  # a terrain this many times longer than wide is viewed along its length


def default_view(hf, width=640, height=360, fov_y=60.0) -> View:
    """A three-quarter view of the whole terrain from the south-west, above its highest point; a long thin strip
    (``STRIP_ASPECT``) is viewed along its length instead (``strip_view``), where a view of the whole would
    make it a sliver under a pixel wide."""
    w, d = hf.extent
    if max(w, d) >= STRIP_ASPECT * min(w, d):
        return strip_view(hf, width, height, fov_y)
    lo, hi = hf.height_range
    ox, oy, oz = hf.origin
    size = max(w, d)
    eye = np.array([ox + 0.25 * w, oy - 0.08 * d, oz + hi + 0.12 * size])
    target = np.array([ox + 0.55 * w, oy + 0.55 * d, oz + lo])
    return View(eye, target, fov_y, width, height, near=max(0.5, size * 1e-5), far=size * 6 + (hi - lo) * 4)


def strip_view(hf, width=640, height=360, fov_y=60.0) -> View:
    """A view along a long thin terrain (world metres): from above the middle of its west or south end, half its
    width above the end's highest sample, pitched 20 degrees down along its length."""
    w, d = hf.extent
    ox, oy, oz = hf.origin
    lo, hi = hf.height_range
    short, size = min(w, d), max(w, d)
    along_x = w >= d
    near_end = hf.heights[:, :2] if along_x else hf.heights[:2, :]
    z = oz + float(np.max(near_end)) + 0.5 * short
    eye = np.array([ox, oy + 0.5 * d, z]) if along_x else np.array([ox + 0.5 * w, oy, z])
    ahead = np.array([4.0 * short, 0.0]) if along_x else np.array([0.0, 4.0 * short])
    target = np.array([eye[0] + ahead[0], eye[1] + ahead[1], z - np.tan(np.radians(20.0)) * 4.0 * short])
    near = max(1e-3, min(0.5, 0.05 * short))
    return View(eye, target, fov_y, width, height, near=near, far=size * 6 + (hi - lo) * 4)
