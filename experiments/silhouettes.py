"""Who is right where the ray caster and the reference disagree: both against an exact CPU intersection.

The pixels where both the ray caster and the full-resolution reference show terrain but their distances differ by
more than ``TOLERANCE`` (relative) lie on silhouettes, where a ray grazes a ridge. Each such pixel's ray is
intersected exactly (``experiments.exact_hits``: float64, the reference's triangles) and counted as the ray
caster's (within ``AGREE`` of the exact distance), the reference's, or neither's. Run at the frame's bound tau
(the ray caster draws coarser tiles where their error projects under tau) and at a small tau (every tile near
full resolution), so what the level of detail moves is told from what either renderer gets wrong.

    python -m experiments.silhouettes [--size 640x360] [--out reports/silhouettes/NAME.md]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

TOLERANCE = 1e-3  # relative distance difference that marks a disagreeing pixel
AGREE = 1e-4  # relative distance to the exact hit within which a renderer is right
TAUS = (2 / 3, 0.05)  # the default bound and one that draws every tile near full resolution


def disagreements(ctx, hf, view, taus=TAUS, tile_size: int = 256) -> list[dict]:
    """Per tau: disagreeing pixels of the ray caster and the reference for one view, and who the exact hit sides with."""
    from hybrid.reference import ReferenceRenderer
    from hybrid.renderer import Renderer

    from .exact_hits import exact_distances

    rows = []
    with ReferenceRenderer(ctx, hf) as ref, Renderer(ctx, hf, "raycast", tile_size) as rc:
        res_b = ref.render(view, mode="shaded")
        b = np.asarray(res_b.distance)
        for tau in taus:
            res_a = rc.render(view, tau, mode="shaded")
            a = np.asarray(res_a.distance)
            both = res_a.mask & res_b.mask
            rel = np.zeros(both.shape)
            rel[both] = np.abs(a[both] - b[both]) / b[both]
            r, c = np.nonzero(rel > TOLERANCE)
            exact = exact_distances(hf, view, r, c)
            ok_a = np.abs(a[r, c] - exact) <= AGREE * exact
            ok_b = np.abs(b[r, c] - exact) <= AGREE * exact
            rows.append(
                {
                    "tau": tau,
                    "both": int(both.sum()),
                    "disagree": len(r),
                    "raycast right": int(ok_a.sum()),
                    "reference right": int(ok_b.sum()),
                    "neither": int((~ok_a & ~ok_b).sum()),
                    "median rel": float(np.median(rel[both])) if both.any() else float("nan"),
                }
            )
    return rows


def table(ctx, hf, views: dict) -> str:
    """A markdown table of ``disagreements`` for named views."""
    lines = [
        "| view | tau px | pixels both hit | disagree > 1e-3 | ray caster right | reference right | neither "
        "| median rel. distance |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, view in views.items():
        for d in disagreements(ctx, hf, view):
            lines.append(
                f"| {name} | {d['tau']:.3g} | {d['both']} | {d['disagree']} | {d['raycast right']} | "
                f"{d['reference right']} | {d['neither']} | {d['median rel']:.2e} |"
            )
    return "\n".join(lines)


def main(argv=None) -> int:
    """Puget's default view and the first frame of each default flight; the table printed or written to --out."""
    from hybrid.camera.flight import preset
    from hybrid.camera.view import default_view, parse_size
    from hybrid.gl.context import gl_info, shared_context
    from hybrid.terrain.datasets import puget

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="640x360")
    p.add_argument("--out", type=Path)
    a = p.parse_args(argv)
    w, h = parse_size(a.size, "size")
    ctx, hf = shared_context(), puget()
    views = {
        "default": default_view(hf, w, h),
        **{f: preset(f, hf, 8, w, h).view(0) for f in ("flyover", "orbit", "dolly")},
    }
    text = (
        f"# Silhouettes: the ray caster and the reference against exact hits\n\nDevice: {gl_info(ctx).renderer}; "
        f"Puget {hf.rows}x{hf.cols}, {w}x{h}, tiles of 256, shaded.\n\n" + table(ctx, hf, views) + "\n"
    )
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
