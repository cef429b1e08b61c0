"""Edits of a terrain being drawn: the GPU brush pass first, then every strategy follows, each paying what it must.

``TerrainEditor`` applies a brush to the terrain's resident full-resolution heights on the GPU
(``hybrid.gl.brush``), writes the touched window through to the CPU heights, then brings up to date, over what the
window reaches only:

- the tile pyramid's bounds, errors and caches of the touched tiles (``TilePyramid.follow_edit``);
- the raster strategies' node arrays over the nodes the edit reaches, saturation included (``raster.edit``);
- each strategy's resident tiles (``Renderer.follow_edit``, through the strategy's ``follow_edit`` of
  ``hybrid.contract.EditFollowing``): the ray caster's codes and max-mip texels over the window, in place; the
  raster tiles whose samples or node blocks changed, uploaded again into their residency slots;
- the triangle estimate of the touched tiles (the hybrid's per-tile features read it and the pyramid's boxes);
- the reference renderer's height textures over the window and its blocks' bounds (``ReferenceRenderer.follow_edit``).

A terrain opened from a tile store is edited through an in-memory copy of its level 0, each change written
through to the store at once (``hybrid.store_editing``); its renderers then read the new files.

Deformations driven by time (``hybrid.terrain.deform``: a travelling wave, a slow uplift) change the GPU heights
only, at each ``step`` of the editor's clock, over what they reach (``hybrid.gl.deform``: heights = base +
displacements, so a time's heights never depend on the steps before); ``sync`` writes what they changed since the
last sync through to the CPU heights and every renderer follows it as it follows a brush. A brush given while
deformations are held edits the base under them.

Each step is timed (wall ms, with a GL finish for the GPU's part) per edit, in ``EditReport.ms``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from hybrid.contract import TerrainChange
from hybrid.errors import TerrabenchError
from hybrid.gl.brush import GpuHeights
from hybrid.gl.deform import GpuDeformations
from hybrid.reference import ReferenceRenderer
from hybrid.renderer import Renderer
from hybrid.store_editing import StoreEditing
from hybrid.terrain.deform import Deformation, deform_params
from hybrid.terrain.edit_log import EditLog, check_log
from hybrid.terrain.edits import Brush, Window
from hybrid.terrain.heightfield import HeightField
from hybrid.terrain.stored import StoredTerrain
from hybrid.tiles.store import StorePyramid
from raster.edit import edit_state, follow_nodes
from raster.quadtree import GPU_BETA


@dataclass
class EditReport:
    """What one edit changed and cost: the window of samples (rows, columns), the tiles touched, the resident
    tiles refreshed per strategy, wall ms per step (``brush``, ``sync``, ``store``, ``pyramid``, ``raster_nodes``,
    per strategy name, ``estimate``, ``reference``), and for a stored terrain the files and bytes written through."""

    window: Window
    tiles: int = 0
    refreshed: dict = field(default_factory=dict)
    ms: dict = field(default_factory=dict)
    store_files: int = 0
    store_bytes: int = 0


def _timed(ctx, report: EditReport, name: str, fn):
    """fn() with its wall ms (GPU work finished) added to the report under name."""
    t0 = time.perf_counter()
    out = fn()
    if ctx is not None:
        ctx.finish()
    report.ms[name] = report.ms.get(name, 0.0) + (time.perf_counter() - t0) * 1e3
    return out


class TerrainEditor:
    """The GPU heights of one in-memory terrain and the renderers drawing it, kept up to date edit by edit."""

    def __init__(
        self, ctx, hf: HeightField, renderer: Renderer | None = None, reference: ReferenceRenderer | None = None
    ):
        for r in (renderer, reference):
            if r is not None and r.hf is not hf:
                raise TerrabenchError("an editor's renderers must draw the terrain it edits")
        self.ctx, self.hf, self.renderer, self.reference = ctx, hf, renderer, reference
        # a tile store is edited through an in-memory copy, each change written through to the store
        self.stored = StoreEditing(hf) if isinstance(hf, StoredTerrain) else None
        self.cpu = hf if self.stored is None else self.stored.mem
        if self.stored is None and renderer is not None:
            _node_state(renderer)
        self.gpu = GpuHeights(ctx, self.cpu)
        self.deforms: GpuDeformations | None = None
        self.pending: list[Window] = []  # what deformations changed since the last sync

    def apply(self, brush: Brush) -> EditReport:
        """Apply one brush (world metres, the terrain's frame) and bring every renderer up to date."""
        report = EditReport(Window(0, 0, 0, 0))
        edit = self.gpu.edit if self.deforms is None else self.deforms.edit
        report.window = win = _timed(self.ctx, report, "brush", lambda: edit(brush))
        return self._follow(win, report)

    def deform(self, deformation: Deformation, start: float, end: float) -> None:
        """Add a deformation driven by time (world metres, the terrain's frame; start and end in seconds on the
        editor's clock): the GPU heights follow it from the next ``step``, the CPU copy and renderers at ``sync``."""
        p = deform_params(deformation, self.hf, start, end)
        if self.deforms is None:
            self.deforms = GpuDeformations(self.gpu)
        self.deforms.add(p)

    def step(self, t: float) -> list[Window]:
        """Set the GPU heights to clock time t (s) where the deformations moved (GPU only, no CPU work beyond the
        pass); returns those windows of samples."""
        if self.deforms is None:
            return []
        wins = self.deforms.step(t)
        self.pending += wins
        return wins

    def sync(self) -> EditReport:
        """Write what the deformations changed since the last sync through to the CPU heights and bring every
        renderer up to date over it; the report's window bounds every window followed."""
        report = EditReport(Window(0, 0, 0, 0))
        wins, self.pending = merged(self.pending), []
        for w in wins:
            _timed(self.ctx, report, "sync", lambda w=w: self._write_through(w))
            report.window = report.window.union(w)
        for w in wins:
            self._follow(w, report)
        return report

    def _write_through(self, win: Window) -> None:
        """Copy a window of the GPU heights into the CPU heights."""
        self.cpu.heights[win.slices()] = self.gpu.read(win)

    def _follow(self, win: Window, report: EditReport) -> EditReport:
        """Bring every renderer up to date after the samples of a window changed in the CPU heights."""
        if win.empty:
            return report
        if self.stored is not None:
            wrote = _timed(None, report, "store", lambda: self.stored.write(win))
            report.store_files += wrote.files
            report.store_bytes += wrote.bytes
        if self.renderer is not None:
            self._follow_renderer(self.renderer, win, report)
        if self.reference is not None:
            _timed(self.ctx, report, "reference", lambda: self.reference.follow_edit(win))
        return report

    def _follow_renderer(self, r: Renderer, win: Window, report: EditReport) -> None:
        """Bring a renderer up to date after the window changed: its pyramid, the raster node arrays, each
        strategy's resident tiles and the triangle estimate."""
        keys = _timed(None, report, "pyramid", lambda: self._follow_pyramid(r, win))
        report.tiles += len(keys)
        r.tiles_changed(keys)
        beta = _raster_beta(r)
        nodes: list[Window] = []
        if beta is not None:
            nodes = _timed(
                None,
                report,
                "raster_nodes",
                lambda: follow_nodes(self.hf, r.pyramid.n, win, beta) if self.stored is None else self.stored.rewritten,
            )
        change = TerrainChange(win, frozenset(keys), r.pyramid.n, tuple(nodes))
        for name in r.strategies:
            report.refreshed[name] = _timed(self.ctx, report, name, lambda n=name: r.follow_edit(n, change))
        if r.triangles is not None:
            _timed(None, report, "estimate", lambda: r.follow_estimate(change))

    def _follow_pyramid(self, r: Renderer, win: Window) -> list:
        """The renderer's pyramid after the window changed: updated in place, or for a store the written bounds."""
        if self.stored is None:
            return r.pyramid.follow_edit(win)
        assert isinstance(r.pyramid, StorePyramid)  # a stored terrain's renderer reads the store
        return r.pyramid.follow_write(self.stored.pyramid, win)

    def release(self) -> None:
        """Free the GPU heights and deformations (not the renderers)."""
        if self.deforms is not None:
            self.deforms.release()
        self.gpu.release()

    def __enter__(self) -> TerrainEditor:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def replay(editor: TerrainEditor, log: EditLog, time: float | None = None) -> list[EditReport]:
    """Apply every edit of a log (checked for the editor's terrain first), in order, one report per edit; then
    its deformations at clock time ``time`` (s; None: the last one's end), written through (one report more)."""
    check_log(log, editor.hf)
    reports = [editor.apply(e.brush) for e in log.edits]
    if log.deformations:
        for d in log.deformations:
            editor.deform(d.deformation, d.start, d.end)
        editor.step(max(d.end for d in log.deformations) if time is None else time)
        reports.append(editor.sync())
    return reports


def merged(wins: list[Window]) -> list[Window]:
    """Windows of samples with those that overlap or touch merged into their union, until none do."""
    out: list[Window] = []
    for w in wins:
        while True:
            hit = next((o for o in out if o.i0 <= w.i1 and w.i0 <= o.i1 and o.j0 <= w.j1 and w.j0 <= o.j1), None)
            if hit is None:
                break
            out.remove(hit)
            w = w.union(hit)
        out.append(w)
    return out


def _raster_beta(r: Renderer) -> float | None:
    """The beta of the renderer's raster node arrays (its first raster strategy's), or None: no raster strategy."""
    raster = [n for n in r.strategies if r.kind(n) == "raster"]
    return float(getattr(r.strategies[raster[0]], "beta", GPU_BETA)) if raster else None


def _node_state(r: Renderer) -> None:
    """Make the rect_nodes state of the renderer's raster node arrays before any edit (it measures what an edit
    changes against the heights before it)."""
    beta = _raster_beta(r)
    if beta is not None:
        edit_state(r.hf, r.pyramid.n, beta)
