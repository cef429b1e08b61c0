"""Any grid size, checked end to end through the CLI: a long strip wider than one GL texture, drawn in memory, and
a square past what the reference would hold in one texture, drawn through ``prepare``'s tile store.

Both are written as tiled GeoTIFFs with rasterio, as users' DEMs come. Every method renders each view with
``terrabench render`` in its own process (its peak resident memory measured); each image is compared with the
full-resolution reference (coverage agreement, crack pixels: ``experiments.metrics``), and the reference with an
exact CPU intersection at sampled pixels (``experiments.exact_hits``). A method that refuses says why (exit 2):
the table shows its message. Run: ``python -m experiments.bench_sizes --work DIR --out reports/sizes/NAME.md``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hybrid.camera.view import View, default_view

METHODS = ("reference", "raycast", "raster", "raster_gs", "hybrid", "fullres", "tin")
SAMPLED_PIXELS = 400


_LAUNCH = """import os, sys
pid = os.fork()
if pid == 0:
    os.execvp(sys.argv[2], sys.argv[2:])
_, status, usage = os.wait4(pid, 0)
open(sys.argv[1], "w").write(str(usage.ru_maxrss))
sys.exit(os.waitstatus_to_exitcode(status))
"""
"""Runs a command and writes its peak RSS (KiB) to a file. Linux counts in a child's peak the resident size of the
process it was forked from, so the command is started from this small launcher, not from the benchmark's own
process (which holds the images)."""


@dataclass
class Outcome:
    """One method's render of one view: exit status, seconds, peak RSS (GiB), message, and the distance image."""

    code: int
    seconds: float
    peak_gib: float
    message: str
    distance: np.ndarray | None


def write_geotiff(path: Path, rows: int, cols: int, read_rows, spacing: float = 10.0, band: int = 512) -> Path:
    """A tiled float32 GeoTIFF (UTM 10N, north up) of rows x cols samples; read_rows(r0, r1) gives rows south to
    north, written band by band."""
    import rasterio
    from rasterio.transform import from_origin

    profile = dict(
        driver="GTiff",
        width=cols,
        height=rows,
        count=1,
        dtype="float32",
        crs="EPSG:32610",
        transform=from_origin(500000.0, 5200000.0 + rows * spacing, spacing, spacing),
        tiled=True,
        blockxsize=256,
        blockysize=256,
        BIGTIFF="IF_SAFER",
    )
    with rasterio.open(path, "w", **profile) as dst:
        for r0 in range(0, rows, band):
            r1 = min(rows, r0 + band)
            south_up = read_rows(r0, r1)
            window = rasterio.windows.Window(0, rows - r1, cols, r1 - r0)  # file rows run north to south
            dst.write(south_up[::-1].astype(np.float32), 1, window=window)
    return path


def strip_rows(cols: int, seed: int = 3):
    """read_rows of a rough 2-D profile, the same in every row plus small noise: a long thin test strip."""
    rng = np.random.default_rng(seed)
    base = np.cumsum(rng.normal(0.0, 1.5, cols)) + 40.0 * np.sin(np.arange(cols) / 300.0)

    def read(r0: int, r1: int) -> np.ndarray:
        return np.stack([base + 0.5 * r for r in range(r0, r1)]).astype(np.float32)

    return read


def render(dataset: Path, method: str, view: View, out: Path, extra: list[str]) -> Outcome:
    """``terrabench render`` of one view in its own process; its exit code, time, peak RSS and distance image."""

    def fmt(v):
        return ",".join(f"{x:.6f}" for x in v)

    cmd = [
        sys.executable,
        "-m",
        "experiments",
        "render",
        "--dataset",
        str(dataset),
        "--method",
        method,
        "--out",
        str(out),
        "--eye",
        fmt(view.eye),
        "--target",
        fmt(view.target),
        "--fov",
        str(view.fov_y),
        "--size",
        f"{view.width}x{view.height}",
        "--near",
        repr(view.near),
        "--far",
        repr(view.far),
        "--shading",
        "shaded",
        *extra,
    ]
    peak_file = out.with_suffix(".peak")
    t0 = time.perf_counter()
    run = subprocess.run([sys.executable, "-c", _LAUNCH, str(peak_file), *cmd], capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    code, out_text, err_text = run.returncode, run.stdout, run.stderr
    peak_kib = int(peak_file.read_text()) if peak_file.exists() else 0
    depth = out.with_suffix(".depth.npy")
    distance = np.load(depth) if code == 0 and depth.exists() else None
    lines = (err_text if code else out_text).strip().splitlines() or [""]
    return Outcome(code, seconds, peak_kib / 2**20, lines[-1] if code else lines[0], distance)


@dataclass
class Frame:
    """What experiments.metrics reads of a render: its distance image (inf for sky)."""

    distance: np.ndarray

    @property
    def colour(self) -> np.ndarray:
        """A placeholder of the image's shape (coverage reads only distances)."""
        return np.empty(self.distance.shape + (3,), np.uint8)


def reference_against_exact(hf, view: View, distance: np.ndarray, seed: int = 0) -> tuple[float, float, int]:
    """(coverage agreement, largest relative distance difference, pixels both hit) of the reference image against
    the exact CPU intersection at SAMPLED_PIXELS random pixels away from silhouettes."""
    from experiments.exact_hits import exact_distances
    from experiments.metrics import near_silhouettes

    rng = np.random.default_rng(seed)
    rows, cols = rng.integers(0, view.height, SAMPLED_PIXELS), rng.integers(0, view.width, SAMPLED_PIXELS)
    keep = ~near_silhouettes(distance)[rows, cols]
    rows, cols = rows[keep], cols[keep]
    exact = exact_distances(hf, view, rows, cols)
    got = distance[rows, cols].astype(np.float64)
    both = np.isfinite(exact) & np.isfinite(got)
    rel = float(np.max(np.abs(got[both] - exact[both]) / exact[both])) if both.any() else float("nan")
    return float(np.mean(np.isfinite(exact) == np.isfinite(got))), rel, int(both.sum())


def check_views(name: str, dataset: Path, hf, views: list[View], work: Path, extra: list[str]) -> list[str]:
    """Markdown table rows: every method on every view of one dataset, against the reference."""
    from experiments.metrics import coverage_errors

    rows = []
    for k, view in enumerate(views):
        outcomes = {m: render(dataset, m, view, work / f"{name}-v{k}-{m}.png", extra) for m in METHODS}
        ref = outcomes["reference"]
        exact = reference_against_exact(hf, view, ref.distance) if ref.distance is not None else None
        for m, o in outcomes.items():
            cells = [name, str(k), m, str(o.code), f"{o.seconds:.1f}", f"{o.peak_gib:.2f}"]
            if o.distance is not None and ref.distance is not None:
                cov = coverage_errors(Frame(o.distance), Frame(ref.distance))
                cells += [
                    f"{float(np.isfinite(o.distance).mean()) * 100:.1f}",
                    f"{(1 - cov['coverage_mismatch']) * 100:.3f}",
                    str(cov["crack_px"]),
                ]
            else:
                cells += ["", "", ""]
            cells.append(f"{exact[0] * 100:.2f} / {exact[1]:.1e} ({exact[2]} px)" if m == "reference" and exact else "")
            cells.append(o.message.replace("|", "/")[:160] if o.code else "")
            rows.append("| " + " | ".join(cells) + " |")
            print(rows[-1], flush=True)
    return rows


HEADER = (
    "| dataset | view | method | exit | s | peak GiB | terrain % | coverage agreement % | cracks px | "
    "reference vs exact: agreement % / max rel. distance (pixels) | message |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|"
)


def main(argv=None) -> int:
    """Write the strip and square GeoTIFFs, prepare the square, render and compare every method; write the table."""
    from hybrid.terrain.sources import TerrainSource

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--work", type=Path, required=True, help="folder for the GeoTIFFs, the store and the images")
    p.add_argument("--out", type=Path, required=True, help="the markdown report to write")
    p.add_argument("--strip", type=int, default=20000, help="columns of the 2-row strip")
    p.add_argument("--square", type=int, default=16385, help="samples a side of the square (0: skip it)")
    p.add_argument("--size", default="320x180")
    a = p.parse_args(argv)
    a.work.mkdir(parents=True, exist_ok=True)
    w, h = (int(v) for v in a.size.split("x"))
    lines = [
        f"# Any grid size: a {a.strip}x2 strip in memory and a {a.square}² square through prepare",
        "",
        _environment(),
        "",
        HEADER,
    ]
    strip = write_geotiff(a.work / "strip.tif", 2, a.strip, strip_rows(a.strip))
    shf = TerrainSource(str(strip)).load()
    lines += check_views("strip", strip, shf, [default_view(shf, w, h)], a.work, [])
    if a.square:
        lines += _square(a.square, a.work, w, h)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {a.out}")
    return 0


def _square(size: int, work: Path, w: int, h: int) -> list[str]:
    """Table rows of the square: its GeoTIFF written (once), prepared (resumed if done) and drawn by every method."""
    from hybrid.terrain.grid_sources import FractalSource
    from hybrid.terrain.stored import open_store

    tif = work / "square.tif"
    if not tif.exists():
        write_geotiff(tif, size, size, FractalSource(size, seed=1).read_rows)
    store = work / "square.store"
    subprocess.run(
        [sys.executable, "-m", "experiments", "prepare", str(tif), "--out", str(store), "--quiet"], check=True
    )
    qhf = open_store(store)
    return check_views("square", store, qhf, [default_view(qhf, w, h)], work, [])


def _environment() -> str:
    from hybrid.gl.context import gl_info, shared_context

    info = gl_info(shared_context(None))
    return f"Device: {info.renderer}; {os.cpu_count()} CPU cores; {time.strftime('%Y-%m-%d')}."


if __name__ == "__main__":
    raise SystemExit(main())
