"""Temporal stability over a flight: how much a method's frames change beyond what the reference's change.

Popping is a level-of-detail switch that moves the drawn surface in one frame. The frame-to-frame change of
depth, or of depth error, cannot show it on its own: while the camera moves, every pixel slides over the
surface and its depth error changes with the mesh under it, most in the near field. Over three consecutive
frames of a smooth flight that sliding is nearly linear in time, so the second difference of a pixel's
relative depth error against the reference,

    e_k = (d_k - d_ref,k) / d_ref,k,      pop_k = |e_{k+1} - 2 e_k + e_{k-1}|,

cancels it, while a switch between k-1 and k (or k and k+1) leaves a step as large as the surface moved.
Creases the camera slides over leave thin lines; a 5 x 5 median filter keeps only patches (a switched
tilelet covers many pixels). ``pop_px`` counts pixels whose filtered value exceeds POP_STEP.

A mesh can flag pixels without any switch: where the camera slides along a crease at a grazing angle the
error's change is not linear over three frames. ``static_pop_pixels`` measures that floor: the same three
views drawn with the middle frame's tiles and level of detail held (the leaves selected from its eye), so
that nothing switches; pixels a method flags beyond its static floor are level-of-detail popping.

The cancellation needs a slow camera: where the terrain moves across the image by more than POP_MAX_FLOW_PX
a frame (``image_flow``, 90th percentile over the reference's terrain pixels) every pixel sees another part
of the surface each frame, and pop_px is left out (NaN). The dolly flight moves the image by about a pixel
a frame at most; the orbit and flyover presets by tens of pixels.
"""

from __future__ import annotations

import numpy as np

from .metrics import check_pair, near_silhouettes

POP_STEP = 1e-3  # a step of the relative depth error (0.1 % of the distance) that counts as popping
POP_FILTER_PX = 5  # side of the median filter that keeps patches and drops creases (pixels)
POP_MAX_FLOW_PX = 2.0  # image motion a frame (pixels, 90th percentile) up to which popping is measured


def _ratio(x: float, ref: float) -> float:
    """x / ref, with 0 / 0 = 1 (no change, as the reference) and x / 0 = inf."""
    return float(x / ref) if ref > 0 else (1.0 if x == 0 else float("inf"))


def depth_error_steps(frames, refs) -> np.ndarray:
    """Per pixel (H x W): the 5 x 5 median of |e_{k+1} - 2 e_k + e_{k-1}| for three consecutive frames and their
    references (e the relative depth error), 0 where a pixel is sky or near a silhouette in any of the six."""
    from scipy.ndimage import median_filter

    if len(frames) != 3 or len(refs) != 3:
        raise ValueError("depth_error_steps needs three consecutive frames and their three references")
    for f in (*frames, *refs):
        check_pair(frames[0], f)
    ok = np.ones(frames[0].distance.shape, dtype=bool)
    for f in (*frames, *refs):
        ok &= np.isfinite(f.distance) & ~near_silhouettes(f.distance)
    e = []
    for f, r in zip(frames, refs):
        d, rd = np.where(ok, f.distance, 1.0), np.where(ok, r.distance, 1.0)  # float64, finite
        e.append((d - rd) / rd)
    step = np.where(ok, np.abs(e[2] - 2.0 * e[1] + e[0]), 0.0)
    return median_filter(step, size=POP_FILTER_PX, mode="constant")


def pop_pixels(prev, cur, nxt, ref_prev, ref_cur, ref_next) -> int:
    """Popping around the middle frame of three: pixels whose filtered second difference of relative depth
    error (``depth_error_steps``) exceeds POP_STEP."""
    return int(np.count_nonzero(depth_error_steps((prev, cur, nxt), (ref_prev, ref_cur, ref_next)) > POP_STEP))


def image_flow(ref, view, prev_view) -> float:
    """How far the terrain moves across the image from the previous frame (pixels, 90th percentile over the
    reference's terrain pixels): each pixel's reference hit point projected into the previous view; 0 when
    the frame has no terrain."""
    ok = np.isfinite(ref.distance)
    if not ok.any():
        return 0.0
    rows, cols = np.nonzero(ok)
    points = view.eye + view.pixel_rays(rows, cols) * ref.distance[ok].astype(np.float64)[:, None]
    q = prev_view.project(points)
    return float(np.percentile(np.hypot(q[:, 0] - (cols + 0.5), q[:, 1] - (rows + 0.5)), 90))


def popping(frames, refs, views) -> dict:
    """Popping around the middle of three consecutive frames (with their references and views): flow_px, the
    larger ``image_flow`` of the two steps, and pop_px (``pop_pixels``), NaN where flow_px > POP_MAX_FLOW_PX."""
    flow = max(image_flow(refs[1], views[1], views[0]), image_flow(refs[2], views[2], views[1]))
    pop = pop_pixels(*frames, *refs) if flow <= POP_MAX_FLOW_PX else np.nan
    return {"flow_px": flow, "pop_px": pop}


def temporal_errors(prev, cur, ref_prev, ref_cur) -> dict:
    """Colour change between consecutive frames against the reference's.

    change_ratio = mean |cur - prev| / mean |ref_cur - ref_prev| (1 = as stable as the reference);
    error_flicker = mean |(cur - ref_cur) - (prev - ref_prev)| in 8-bit units (0 = the error does not move).
    """
    for f in (cur, ref_prev, ref_cur):
        check_pair(prev, f)
    a0, a1 = prev.colour.astype(np.float64), cur.colour.astype(np.float64)
    r0, r1 = ref_prev.colour.astype(np.float64), ref_cur.colour.astype(np.float64)
    ch, rch = np.abs(a1 - a0).mean(), np.abs(r1 - r0).mean()
    return {"change_ratio": _ratio(ch, rch), "error_flicker": float(np.abs((a1 - r1) - (a0 - r0)).mean())}


def static_frames(renderer, views, tau: float, middle) -> list:
    """The three views drawn as ``middle`` (the result of drawing views[1]) was: its tiles, strategies and the
    leaves selected from its eye held (``lod_eye``), so no level of detail changes between them."""
    eye = tuple(float(x) for x in views[1].eye)
    return [renderer.render(v, tau, plans=middle.plans, lod_eye=eye) for v in views]


def static_pop_pixels(renderer, views, refs, tau: float, middle) -> int:
    """``pop_pixels`` of the three views drawn with the middle frame's level of detail held (``static_frames``):
    what the metric flags on a mesh that does not switch."""
    return pop_pixels(*static_frames(renderer, views, tau, middle), *refs)
