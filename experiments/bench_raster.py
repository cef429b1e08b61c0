"""Benchmark of the raster strategies: tables as DataFrames; `python -m experiments.bench_raster` prints them.

1. Triangles against max vertical error on Puget tiles: restricted quadtree (plain errors with full fans, and
   lean: every midpoint no finer neighbour or side error needs dropped; morph-safe errors at beta 0.7; at the GPU
   strategies' beta with lean leaves under full_res "exact" (full-resolution leaves keep every midpoint); the same
   with both fans in one error, as a periodic extension's nodes hold them near its seams; and what raster and
   raster_gs draw by default, full_res "lean": full-resolution leaves lean too, turning cells' two triangles more
   counted)
   vs pymartini (RTIN), pydelatin and fast-simplification, every max error measured the same way.
2. The GPU leaf selection of a frame's tiles (issued, and finished) and the whole frame with its CPU share:
   planning plus issuing the draw (waits for the GL excluded); on llvmpipe issuing includes the compute
   dispatches, which run inside the call.
3. GPU bytes per tile and representation, next to the paper's 96 bits (12 bytes) per triangle.
4. Geometry-shader tilelet throughput against an indexed triangle list of the same triangles.
5. Tilelet culling gain on a low view.
Timings: wall clock around ctx.finish() (GPU timer queries are wrong on llvmpipe); median of repeats.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from hybrid.errors import TerrabenchError


def puget_tiles(count=4):
    """A few 257² full-resolution tiles of the bundled Puget Sound model (tile size 256)."""
    from hybrid.terrain.datasets import puget
    from hybrid.tiles.pyramid import TilePyramid

    hf = puget(with_texture=False)
    pyr = TilePyramid(hf, 256)
    keys = pyr.keys(0)
    step = max(1, len(keys) // count)
    return hf, [pyr.tile(k) for k in keys[::step][:count]]


TIN_METHODS = (
    "quadtree",
    "quadtree-lean",
    "quadtree-morph",
    "gpu-full-res-exact",
    "gpu-combined",
    "gpu-full-res-lean",
    "martini",
    "delatin",
    "fast-simpl",
)
"""The meshes ``triangles_vs_error`` compares, in its rows' order."""


def triangles_vs_error(tiles, errors=(5.0, 10.0, 20.0, 40.0, 80.0)):
    """Rows (target error, method, triangles summed over tiles, measured max error) for each method."""
    try:
        from pydelatin import Delatin
        from pymartini import Martini
    except ImportError as exc:
        raise TerrabenchError(
            f"the raster benchmark compares with pymartini and pydelatin ({exc.name} is missing): "
            "pip install 'terrabench[bench]'"
        ) from None

    from raster.quadtree import GPU_BETA, error_pyramid

    rows = []
    pyrs = {"quadtree": [error_pyramid(t.heights) for t in tiles]}
    pyrs["quadtree-lean"] = pyrs["quadtree-morph"] = pyrs["quadtree"]
    pyrs["gpu-full-res-lean"] = [error_pyramid(t.heights, GPU_BETA) for t in tiles]  # what raster, raster_gs draw
    pyrs["gpu-full-res-exact"] = pyrs["gpu-full-res-lean"]
    pyrs["gpu-combined"] = [error_pyramid(t.heights, GPU_BETA, side_errors=False) for t in tiles]
    n = tiles[0].n
    martini = Martini(n + 1)
    for e in errors:
        res = {}
        for name in TIN_METHODS:
            tri, err = 0, 0.0
            for i, t in enumerate(tiles):
                h = np.asarray(t.heights, dtype=np.float32)
                if name.startswith(("quadtree", "gpu")):
                    t_tri, t_err = _quadtree_tile(name, pyrs[name][i], h, e)
                else:
                    t_tri, t_err = _tin_tile(name, h, e, n, martini, Delatin)
                tri += t_tri
                err = max(err, t_err)
            res[name] = (tri, err)
        for name, (tri, err) in res.items():
            rows.append(
                (f"{e:g}", name, tri, f"{err:.2f}", f"{tri / res['delatin'][0]:.2f}", f"{tri / res['martini'][0]:.2f}")
            )
    return rows


def _quadtree_tile(name: str, pyramid, h: np.ndarray, e: float) -> tuple:
    """(triangles, measured max error) of one tile's restricted quadtree at error ``e`` under method ``name``."""
    from raster.quadtree import drawn_max_error
    from raster.restriction import TileLod, restrict_frame

    morph = name == "quadtree-morph" or name.startswith("gpu")
    ts = restrict_frame(
        [TileLod((0, 0, 0), pyramid, e)],
        morph=morph,
        use_effective=morph,
        lean=name not in ("quadtree", "quadtree-morph"),
        exact_full_resolution=name != "gpu-full-res-lean",
    )[(0, 0, 0)]
    return ts.triangles, float(drawn_max_error(h, ts.leaves, ts.drop).max())


def _tin_tile(name: str, h: np.ndarray, e: float, n: int, martini, Delatin) -> tuple:
    """(triangles, measured max error, inf where unmeasured) of one tile's TIN at error ``e``: martini's, delatin's
    or fast-simplification's (``raster.tin.build_tin``)."""
    from raster.tin import TinMesh, build_tin, tin_max_error

    if name == "martini":
        mesh = _martini_mesh(martini, h, e)
    elif name == "delatin":
        d = Delatin(h, max_error=e)
        V = np.asarray(d.vertices, dtype=np.float64)
        V[:, 1] = n - V[:, 1]  # delatin's rows run north to south
        mesh = TinMesh(V, np.asarray(d.triangles, dtype=np.int64))
    else:
        mesh = build_tin(h, 1.0, max_error=e, preserve_border=True)
    me, unc = tin_max_error(mesh, h, 1.0)
    return mesh.triangles, me if unc == 0 else float("inf")


def _martini_mesh(martini, h: np.ndarray, e: float):
    """Martini's mesh of a tile meeting error ``e`` at every sample: martini checks its error only at split
    midpoints, so its parameter is bisected until the error measured at every sample meets the target."""
    from raster.tin import TinMesh, tin_max_error

    tile_m = martini.create_tile(h)

    def mesh_at(param):
        v, f = tile_m.get_mesh(param)
        v = v.astype(np.float64)
        return TinMesh(
            np.column_stack([v[:, 0], v[:, 1], h[v[:, 1].astype(int), v[:, 0].astype(int)]]), f.astype(np.int64)
        )

    lo, hi, mesh = 0.0, e, mesh_at(0.0)
    for _ in range(7):
        mid = 0.5 * (lo + hi)
        cand = mesh_at(mid)
        if tin_max_error(cand, h, 1.0)[0] <= e:
            lo, mesh = mid, cand
        else:
            hi = mid
    return mesh


def _issue_and_total_ms(fn, repeats, ctx):
    """Medians (ms) of the wall clock until fn returns (its commands issued) and until the GL has finished them."""
    issue, total = [], []
    for _ in range(repeats):
        ctx.finish()
        t0 = time.perf_counter()
        fn()
        issue.append((time.perf_counter() - t0) * 1e3)
        ctx.finish()
        total.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(issue)), float(np.median(total))


def selection_rows(ctx, repeats=5):
    """Rows (strategy, tiles, selection issue ms, selection ms, frame ms, plan ms, issue ms, CPU ms, triangles):
    the GPU leaf selection alone (issued, and finished), and the whole frame with its CPU share (planning plus
    issuing the draw, its waits for the GL excluded: ``FrameStats.issue_ms``)."""
    from hybrid.camera.flight import preset
    from hybrid.renderer import Renderer
    from hybrid.terrain.datasets import puget
    from raster.selection import TileletSelection

    hf = puget()
    view = preset("flyover", hf, 8).view(3)
    rows: list[tuple] = []
    for name in ("raster", "raster_gs"):
        with Renderer(ctx, hf, name, tile_size=128) as r:
            r.render(view)
            items = r._items(name, r.plan(view), set())
            strategy = r.strategies[name]
            assert isinstance(strategy, TileletSelection)  # raster and raster_gs select leaves on the GPU
            issue, sel = _issue_and_total_ms(
                lambda strategy=strategy, items=items: strategy.select_leaves(view, items, 2 / 3), repeats, ctx
            )
            res = [r.render(view).stats for _ in range(repeats)]
            plan, draw_issue = np.median([x.plan_ms for x in res]), np.median([x.issue_ms for x in res])
            cpu = np.median([x.cpu_ms for x in res])
            rows.append(
                (
                    name,
                    len(items),
                    f"{issue:.2f}",
                    f"{sel:.1f}",
                    f"{np.median([x.wall_ms for x in res]):.1f}",
                    f"{plan:.2f}",
                    f"{draw_issue:.2f}",
                    f"{cpu:.2f}",
                    res[-1].counters["triangles"],
                )
            )
    return rows


def memory_rows(ctx, hf, tiles):
    """Rows (representation, bytes per tile, triangles, bytes per triangle); the tilelet strategies' resident
    bytes per tile (heights, nodes, skirts, commands), then what their frame arena holds per drawn leaf."""
    from raster.arena import LAYOUTS
    from raster.tilelets import TileletStrategy
    from raster.tin import TinStrategy
    from raster.trianglelist import TriangleListStrategy

    rows = []
    tile = tiles[0]
    full_tris = 2 * tile.n * tile.n
    for name, make in (
        ("tilelets resident (raster, raster_gs)", lambda: TileletStrategy(ctx, hf)),
        ("fullres list", lambda: TriangleListStrategy(ctx, hf)),
        ("tin 90% reduced", lambda: TinStrategy(ctx, hf, reduction=0.9)),
    ):
        s = make()
        g = s.upload(tile)
        tris = getattr(g, "triangles", full_tris)
        rows.append((name, g.nbytes, tris, f"{g.nbytes / tris:.1f}"))
        g.release()
        s.release()
    record_bytes, vertex_bytes, index_bytes = LAYOUTS["exact"]  # an "exact"-rule leaf, as reports/bench give it
    for name, per_leaf in (
        ("raster arena, a drawn leaf", vertex_bytes + index_bytes),
        ("raster_gs arena, a drawn leaf", record_bytes),
    ):
        rows.append((name, per_leaf, 8, f"{per_leaf / 8:.1f}"))
    rows.append(("paper: list indices", full_tris * 12, full_tris, "12.0 (96 bits)"))
    return rows


def _top_view(hf, width=320, height=180):
    from hybrid.camera.view import View

    w, d = hf.extent
    ox, oy, oz = hf.origin
    c = np.array([ox + w / 2, oy + d / 2, oz])
    return View(c + np.array([0.0, -0.3 * d, 2.5 * max(w, d)]), c, 40, width, height, near=10.0, far=20 * max(w, d))


def throughput_rows(ctx, repeats=5):
    """Rows comparing the geometry-shader tilelets with the indexed triangles of the same leaves (Mtri/s)."""
    from hybrid.renderer import Renderer
    from hybrid.terrain.datasets import puget

    hf = puget(with_texture=False, size=513)
    view = _top_view(hf)
    rows = []
    with Renderer(ctx, hf, "raster_gs", tile_size=256) as gs, Renderer(ctx, hf, "raster", tile_size=256) as inst:
        for leaf_tau in (0.05, 2.0 / 3.0):
            ms = {}
            for name, r in (("gs", gs), ("inst", inst)):
                r.render(view, mode="shaded", leaf_tau=leaf_tau, culling=False)
                res = [r.render(view, mode="shaded", leaf_tau=leaf_tau, culling=False) for _ in range(repeats)]
                ms[name] = float(np.median([x.stats.draw_ms for x in res]))
                tris = res[-1].stats.counters["triangles"]
            rows.append(
                (
                    f"{leaf_tau:g}",
                    tris,
                    f"{ms['gs']:.1f}",
                    f"{tris / ms['gs'] / 1e3:.2f}",
                    f"{ms['inst']:.1f}",
                    f"{tris / ms['inst'] / 1e3:.2f}",
                    f"{ms['inst'] / ms['gs']:.2f}",
                )
            )
    return rows


def culling_rows(ctx, repeats=5):
    """Rows (culling, tilelets drawn, culled, triangles, ms) on a low view with much of each tile outside."""
    from hybrid.camera.view import View
    from hybrid.renderer import Renderer
    from hybrid.terrain.datasets import puget

    hf = puget(with_texture=False, size=513)
    w, d = hf.extent
    ox, oy, _oz = hf.origin
    eye = np.array([ox + 0.3 * w, oy + 0.3 * d, hf.ground_height(ox + 0.3 * w, oy + 0.3 * d) + 60.0])
    view = View(eye, eye + np.array([3000.0, 1000.0, -600.0]), 40, 320, 180, near=1.0, far=10 * w)
    r = Renderer(ctx, hf, "raster", tile_size=128)
    rows = []
    try:
        r.render(view, mode="shaded")
        base = {}
        for cull in (False, True):
            res = [r.render(view, mode="shaded", culling=cull) for _ in range(repeats)]
            counted = res[-1]
            ms = float(np.median([x.stats.draw_ms for x in res]))
            s = counted.stats.counters
            base[cull] = ms
            rows.append(("on" if cull else "off", s["tilelets"], s["tilelets_culled"], s["triangles"], f"{ms:.1f}"))
        rows.append(("gain", "", "", "", f"{base[False] / base[True]:.2f}x"))
    finally:
        r.release()
    return rows


def triangle_tables() -> dict[str, pd.DataFrame]:
    """The triangle counts against max vertical error (metres) of every mesh method: CPU only, the same on every
    device (`terrabench bench --which triangles`)."""
    _, tiles = puget_tiles()
    return {
        "1. triangles vs max vertical error, 4 Puget tiles of 257² (160 m spacing); error in metres": pd.DataFrame(
            triangles_vs_error(tiles), columns=["target", "method", "triangles", "max err", "x delatin", "x martini"]
        )
    }


def run(ctx) -> dict[str, pd.DataFrame]:
    """The raster strategies' GPU tables keyed by title (times in ms, memory in bytes); the triangle counts are
    triangle_tables."""
    hf, tiles = puget_tiles()
    tables = (
        (
            "2. GPU leaf selection alone and the whole frame (Puget flyover frame 3, tiles of 128, 640x360)",
            [
                "strategy",
                "tiles",
                "selection issue ms",
                "selection ms",
                "frame ms",
                "plan ms",
                "draw issue ms",
                "CPU ms (plan + draw issue; on a CPU rasterizer with its vertex and compute work: the cpu bench "
                "times the target)",
                "triangles",
            ],
            selection_rows(ctx),
        ),
        (
            "3. GPU bytes per 257² tile",
            ["representation", "bytes", "triangles", "bytes/tri"],
            memory_rows(ctx, hf, tiles),
        ),
        (
            "4. geometry shader vs indexed triangles, same leaves (Puget 513², top view, 320x180)",
            ["leaf tau", "triangles", "GS ms", "GS Mtri/s", "indexed ms", "indexed Mtri/s", "indexed/GS"],
            throughput_rows(ctx),
        ),
        (
            "5. tilelet culling on a low view (Puget 513², tiles of 128)",
            ["culling", "tilelets drawn", "culled", "triangles", "draw ms"],
            culling_rows(ctx),
        ),
    )
    return {title: pd.DataFrame(rows, columns=header) for title, header, rows in tables}


def main() -> None:
    """Run every benchmark and print its table."""
    from hybrid.gl.context import gl_info, shared_context

    from .tables import text_tables

    ctx = shared_context()
    info = gl_info(ctx)
    print(f"terrabench raster benchmark on {info.renderer} ({info.version})\n")
    print(text_tables({**triangle_tables(), **run(ctx)}))


if __name__ == "__main__":
    main()
