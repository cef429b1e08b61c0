"""The contract between the renderer and the tile strategies, and the one shape of a frame's statistics.

A strategy (``raster.*``, ``raycast``) is a GPU class that satisfies ``TileStrategy`` structurally; it
imports nothing above ``hybrid.gl``. The renderer hands it ``TileItem``s front to back and a bound
``FrameTarget``; every renderer returns ``FrameStats`` with the same fields whatever the method.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any, ClassVar, Literal, NamedTuple, Protocol, get_args, runtime_checkable

from hybrid.camera.view import View
from hybrid.errors import TerrabenchError
from hybrid.gl.target import FrameTarget
from hybrid.terrain.edits import Window
from hybrid.tiles.pyramid import Tile, TileKey
from hybrid.tiles.tiletree import SelectedTile

StrategyName = Literal["raster", "raster_gs", "raycast", "fullres", "tin"]
"""Names of the registered tile strategies, for type checkers; ``hybrid.strategies`` is the registry, and
tests/test_registry.py keeps this in step with it."""
Kind = Literal["raster", "raycast"]
"""How a strategy makes pixels: triangles through the rasterizer, or rays in the fragment shader."""
Policy = Literal["raster", "raster_gs", "raycast", "fullres", "tin", "hybrid", "heuristic", "oracle"]
"""How a renderer chooses each tile's strategy (for type checkers; the registry's ``policies()``)."""
Method = Literal["reference", "raster", "raster_gs", "raycast", "fullres", "tin", "hybrid", "heuristic", "oracle"]
"""Anything that renders a view: the full-resolution reference or a policy (the registry's ``methods()``)."""

FullRes = Literal["exact", "lean"]
"""Full-resolution rules of the tilelet strategies: "exact" draws every full-resolution leaf with all its
midpoints, its cells split SW-NE as the reference's (more triangles than the bound asks for, closer to the
reference at a given tau); "lean" lets those leaves drop midpoints by their side errors as all others do (no more
triangles than the bound asks for), their SE and NW cells turning diagonal through a morphed centre post
(raster/select.comp.glsl LEAN_FULL_RES). Both converge to the reference's image as tau falls."""
FULL_RES: tuple[str, ...] = get_args(FullRes)
DEFAULT_FULL_RES: FullRes = "lean"
"""The rule drawn where none is asked for (strategies, renderers, the estimate, ``render``, specs)."""
PRIOR_FULL_RES: FullRes = "exact"
"""The rule drawn before rules were named, whatever the default: what run folders' spec.json and frames and cost
models without the key drew. Config ids leave it unnamed (ids stay as such runs wrote them), and the rows of
policies that draw no tilelets record it."""


class DrawOptions:
    """Base of a strategy's frozen dataclass of draw options (``options_type``; ``raycast.CastOptions``,
    ``raster.options``): a copy with some changed, names checked, and the values as ``draw_tiles`` keywords."""

    def updated(self, **changes) -> Any:
        """A copy with some options changed; unknown names raise TerrabenchError."""
        known = {f.name for f in fields(self)}  # type: ignore[arg-type]
        bad = sorted(set(changes) - known)
        if bad:
            raise TerrabenchError(
                f"unknown {type(self).__name__} option(s) {', '.join(bad)}; known: {', '.join(sorted(known))}"
            )
        return replace(self, **changes) if changes else self  # type: ignore[type-var]

    def values(self) -> dict[str, Any]:
        """The options by name, as keywords of the strategy's ``draw_tiles`` (not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}  # type: ignore[arg-type]

    # names of the options that shape what a tile's upload makes (a texture format): fixed when the strategy is
    # made, passed to its constructor, and refused by a draw that asks for another value
    upload_fields: ClassVar[tuple[str, ...]] = ()

    def upload_options(self) -> dict[str, Any]:
        """The options that shape a tile's upload (``upload_fields``), as the strategy's constructor keywords."""
        return {name: getattr(self, name) for name in self.upload_fields}


def check_flags(options, names: tuple[str, ...]) -> None:
    """Raise TerrabenchError naming the first of ``names`` whose option is not True or False."""
    for name in names:
        if not isinstance(getattr(options, name), bool):
            raise TerrabenchError(f"{name} must be True or False, got {getattr(options, name)!r}")


@runtime_checkable
class GpuTile(Protocol):
    """One tile uploaded by one strategy: its GPU bytes and how to free them."""

    nbytes: int

    def release(self) -> None:
        """Free every GPU object of the tile."""


class TileItem(NamedTuple):
    """One tile of a frame as a strategy draws it: GPU copy, CPU tile and its selection for the view."""

    gpu: Any
    tile: Tile
    selected: SelectedTile


@runtime_checkable
class TileStrategy(Protocol):
    """A way to draw tiles into the shared colour + reversed-Z depth target."""

    kind: Kind
    draw_options: frozenset[str]
    options_type: type[DrawOptions]

    def upload(self, tile: Tile) -> GpuTile:
        """Put one tile on the GPU."""

    def draw_tiles(
        self, target: FrameTarget, view: View, items: Sequence[TileItem], tau: float, **options
    ) -> dict[str, float]:
        """Draw items (front to back) into the bound target at screen-space error tau px; counters back."""

    @property
    def shared_nbytes(self) -> int:
        """GPU bytes the strategy holds for all tiles (terrain texture, buffers), not counting tiles."""

    def release(self) -> None:
        """Free the strategy's own GPU objects (tiles are freed through their GpuTile)."""


@dataclass(frozen=True)
class TerrainChange:
    """What an edit changed, as a strategy follows it: the window of level-0 samples, the pyramid's tiles (every
    level) whose samples or bounds changed, their tile size in cells, and per global level the window of raster
    node indices whose values changed (``raster.edit.follow_nodes``; empty where no raster strategy draws)."""

    window: Window
    tiles: frozenset[TileKey]
    tile_size: int
    nodes: tuple[Window, ...] = ()


@runtime_checkable
class EditFollowing(Protocol):
    """A strategy that follows edits of the terrain it draws (``hybrid.editing``)."""

    def follow_edit(
        self, change: TerrainChange, resident: Sequence[tuple[TileKey, GpuTile]], tile: Callable[[TileKey], Tile]
    ) -> tuple[int, list[TileKey]]:
        """Bring the resident tiles (key, GPU tile) up to date after ``change``, given ``tile(key)`` after it:
        (tiles brought up to date in place, keys of those the renderer must upload again)."""


class SkirtedStrategy(TileStrategy, Protocol):
    """A raster strategy that hangs skirts (draw option ``skirts``) from tile edges facing ray-cast tiles; the
    renderer draws them after every tile, so no skirt lies inside a ray-cast tile's box at its pre-pass."""

    def draw_skirts(self, target: FrameTarget, view: View) -> None:
        """Draw the skirts selected by the last draw_tiles call."""


class TriangleEstimator(Protocol):
    """Triangles a raster strategy would draw for tiles at a view, computed on the CPU without GL;
    ``build_ms`` is the wall time it has spent on one-time per-tile preparation. With ``background`` set, slow
    preparation is left to a store's loader thread: the tiles it concerns are unknown (NaN) in ``many``, and
    ``waiting`` maps each of them to that work (a callable), for the renderer to hand to the loader."""

    build_ms: float
    background: bool
    waiting: dict

    def __call__(self, key: TileKey, selected: SelectedTile, view: View, tau: float) -> int:
        """Estimated triangle count of tile ``key`` at ``view`` for the bound tau (pixels)."""

    def many(
        self, selected: Sequence[SelectedTile], view: View, tau: float, budget_ms: float | None = None
    ) -> tuple[Any, Any]:
        """(triangle counts, share of them inside the view frustum), (B,) float arrays, of the selected tiles at
        ``view`` for the bound tau (pixels); with ``budget_ms``, per-tile preparation stops after that much wall
        time (at least one tile a call) and the tiles left are NaN in both."""

    def follow_edit(self, change: TerrainChange) -> int:
        """Forget what it prepared for the tiles an edit changed; returns how many."""


@dataclass
class FrameStats:
    """What one frame cost and drew; the same fields from every renderer (milliseconds, bytes, counts).

    wall_ms is what a user waits for: planning plus drawing, wall clock around ctx.finish(); gpu_ms is the
    GL timer query on GPUs and None on software rasterizers; issue_ms is the drawing's CPU share, the wall clock
    until its GL commands are issued less its waits for the GL inside (``hybrid.gl.timing``), so the frame's
    CPU time is plan_ms + issue_ms. tiles_raster and tiles_raycast count tiles by kind
    (raster kinds: raster, raster_gs, fullres, tin); tiles_gs counts those of them drawn by raster_gs.
    gpu_bytes counts resident tiles plus what the strategies hold for all tiles (shared_bytes); uploads and
    evictions are those of this frame. prep_ms is one-time CPU work for tiles seen for the first time (the
    raster mesh's node errors behind the triangle estimate), apart from plan_ms and, like uploads, outside
    wall_ms. With an upload budget, upload_ms and prep_ms are part of wall_ms, fallback_tiles counts the tiles
    drawn from a resident ancestor and pending_uploads the jobs left waiting. adapt_ms is an adapting hybrid's
    CPU time learning from the frame (exploration and refit, ``hybrid.cost.online``), part of wall_ms;
    explored_tiles counts the tiles it gave to a strategy it is learning. choice_reused marks a hybrid's frame drawn
    as its last clear pure choice without planning (``hybrid.cost.reuse``: no features, predictions or learning).
    plans are a mixed policy's tile plans, behind ``tile_rows``.
    """

    wall_ms: float
    plan_ms: float
    draw_ms: float
    gpu_ms: float | None = None
    issue_ms: float | None = None
    tiles: int = 0
    tiles_raster: int = 0
    tiles_raycast: int = 0
    tiles_gs: int = 0
    gpu_bytes: int = 0
    gpu_bytes_raster: int = 0
    gpu_bytes_raycast: int = 0
    shared_bytes: int = 0
    uploads: int = 0
    evictions: int = 0
    upload_ms: float = 0.0
    prep_ms: float = 0.0
    fallback_tiles: int = 0
    pending_uploads: int = 0
    pred_ms: float | None = None
    adapt_ms: float = 0.0
    explored_tiles: int = 0
    choice_reused: bool = False
    counters: dict[str, float] = field(default_factory=dict)
    together_ms: dict[str, float] = field(default_factory=dict)
    plans: list = field(default_factory=list, repr=False, compare=False)

    @property
    def cpu_ms(self) -> float | None:
        """The frame's CPU time, ms: plan_ms + issue_ms + adapt_ms (None where the issue time was not measured)."""
        return None if self.issue_ms is None else self.plan_ms + self.issue_ms + self.adapt_ms

    @property
    def tile_rows(self) -> list[dict]:
        """One row per tile of a mixed policy's frame (its features, predictions and choice); built when asked, so
        a frame nobody tabulates does not pay for it."""
        return [p.row() for p in self.plans]

    def row(self) -> dict[str, Any]:
        """One flat table row: every scalar field, the counters and ``together_<strategy>_ms``."""
        d = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("counters", "together_ms", "plans")}
        return {**d, **self.counters, **{f"together_{k}_ms": v for k, v in self.together_ms.items()}}
