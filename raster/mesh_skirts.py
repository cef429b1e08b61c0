"""Skirts of the baseline meshes (full-resolution list, decimated TIN), which are drawn unstitched.

Each selected tile is drawn at its own level, so where two tiles of different levels meet (a T-junction) or two
TINs were decimated apart, their surfaces differ along the shared side and a ray can pass between them. A skirt
is a vertical curtain hanging from a tile's side. It is drawn on every side that faces a selected neighbour of
another level or with another surface along it (same-level tiles of one grid share their border samples), as
deep as the two tiles' drawn surfaces differ anywhere along that side, measured from their border profiles, plus
``MARGIN`` of the tile's sample spacing, so it reaches below the lower surface rather than to it. Where a TIN's
border strays inside its square, a flange joins it to the side (``side_skirt``).

Hanging below the drawn surface, a skirt is hidden from every ray that starts above the terrain sheet except where
the seam lets it through; for rays that start under the sheet it is not drawn (hybrid/gl/edges.glsl, as the
tilelet strategies' skirts). Those rays see a seam from below: for them the same skirts rise above the edges
instead (a second pass, only when some ray may start under the sheet), hidden from them by the sheet in turn.
Side order W, E, S, N as ``SelectedTile.edge_deltas``.
"""

from __future__ import annotations

import numpy as np

from hybrid.terrain.edges import eye_under, grid_frame
from hybrid.tiles.tiletree import NO_NEIGHBOUR, edge_neighbours

STEPS = ((-1, 0), (1, 0), (0, -1), (0, 1))  # tile steps to the W, E, S, N neighbours
MARGIN = 0.01  # of the tile's larger sample spacing: the skirt passes the lower edge


def clip_polygon(polygon: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """The part (k', 3) of a convex polygon (k, 3) inside half-spaces (p, 4) (a, b, c, d): a x + b y + c z + d >= 0
    (Sutherland-Hodgman); empty when none is."""
    poly = list(np.asarray(polygon, dtype=np.float64))
    for plane in planes:
        out = []
        for i, p in enumerate(poly):
            q = poly[(i + 1) % len(poly)]
            dp, dq = p @ plane[:3] + plane[3], q @ plane[:3] + plane[3]
            if dp >= 0:
                out.append(p)
            if (dp >= 0) != (dq >= 0):
                out.append(p + dp / (dp - dq) * (q - p))
        poly = out
    return np.array(poly).reshape(-1, 3)


def rays_may_start_under(hf, view, edge_tops) -> bool:
    """Whether any ray of the view may start under the terrain sheet: over the footprint when the eye lies under
    the ground; from outside when the frustum reaches below an outer edge the eye faces (bounded by that edge's
    highest sample: ``edge_tops`` S, N, W, E metres above the origin z, hybrid.terrain.edges.edge_profiles)."""
    o = grid_frame(hf, view.eye, np.zeros((1, 3)))[0]
    if 0.0 <= o[0] <= hf.cols - 1 and 0.0 <= o[1] <= hf.rows - 1:
        return eye_under(hf, view.eye)
    x0, y0, z0 = (float(c) for c in hf.origin)
    x1, y1 = x0 + hf.extent[0], y0 + hf.extent[1]
    low = float(view.eye[2]) - view.far
    sides = (
        (o[1] < 0, (x0, y0), (x1, y0)),
        (o[1] > hf.rows - 1, (x0, y1), (x1, y1)),  # S, N
        (o[0] < 0, (x0, y0), (x0, y1)),
        (o[0] > hf.cols - 1, (x1, y0), (x1, y1)),
    )  # W, E
    walls = [
        np.array([[*a, low], [*b, low], [*b, z0 + top], [*a, z0 + top]]) - view.eye
        for top, (faces, a, b) in zip(edge_tops, sides)
        if faces
    ]
    planes = view.frustum_planes_rel()[[0, 1, 2, 3, 5]]
    return any(len(clip_polygon(w, planes)) for w in walls)


def grid_border_edges(rows: int, cols: int) -> list[np.ndarray]:
    """Per side W, E, S, N: the (m, 2) sample-index pairs of a rows x cols grid's border edges along it."""
    idx = np.arange(rows * cols, dtype=np.int64).reshape(rows, cols)
    lines = (idx[:, 0], idx[:, -1], idx[0], idx[-1])
    return [np.stack([ln[:-1], ln[1:]], 1) for ln in lines]


def mesh_border_edges(vertices: np.ndarray, faces: np.ndarray, extent) -> list[np.ndarray]:
    """Per side W, E, S, N: the (m, 2) vertex-index pairs of a mesh's border edges (edges of one face) nearest it;
    vertices tile-local metres, extent (width, depth) metres of the tile's square."""
    f = np.asarray(faces, dtype=np.int64)
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    u, counts = np.unique(e, axis=0, return_counts=True)
    border = u[counts == 1]
    mid = 0.5 * (vertices[border[:, 0], :2] + vertices[border[:, 1], :2])
    w, d = extent
    dist = np.stack([mid[:, 0], w - mid[:, 0], mid[:, 1], d - mid[:, 1]], 1)
    side = np.argmin(np.abs(dist), axis=1)
    return [border[side == k] for k in range(4)]


def side_skirt(vertices: np.ndarray, edges: np.ndarray, side: int, extent) -> tuple[np.ndarray, np.ndarray]:
    """One side's skirt line and flange: ((q, 3) points on the side's line, tile-local metres, sorted along it from
    corner to corner; (t, 3, 3) flange triangles).

    The line runs through the side's border vertices moved onto it (a TIN's border may stray inside its square),
    each keeping its height, and on to both corners at the height of the nearest. The flange joins each strayed
    border edge to its image on the line, and the nearest vertex to each corner, covering what the mesh leaves
    open there. Vertices already on the line (a grid's) are kept bit for bit.
    """
    a = 1 if side < 2 else 0  # the coordinate along the side (W, E run north)
    c = 0.0 if side % 2 == 0 else float(extent[1 - a])  # the side's line: W, S at 0, E, N at the far edge
    if not len(edges):
        return np.zeros((0, 3)), np.zeros((0, 3, 3))
    u = np.unique(edges)
    P = np.asarray(vertices[u], dtype=np.float64)
    Q = P.copy()
    moved = np.abs(P[:, 1 - a] - c) > 1e-6 * max(extent)
    Q[moved, 1 - a] = c
    Q[:, a] = np.clip(Q[:, a], 0.0, extent[a])
    order = np.argsort(Q[:, a], kind="stable")
    e = np.searchsorted(u, edges)
    strayed = e[moved[e].any(axis=1)]
    flange = [
        np.stack([P[strayed[:, 0]], P[strayed[:, 1]], Q[strayed[:, 1]]], 1),
        np.stack([P[strayed[:, 0]], Q[strayed[:, 1]], Q[strayed[:, 0]]], 1),
    ]
    line = [Q[order]]
    for end, at in ((order[0], 0.0), (order[-1], float(extent[a]))):
        if abs(Q[end, a] - at) > 1e-6 * max(extent):
            corner = Q[end].copy()
            corner[a] = at
            line.insert(0 if at == 0.0 else len(line), corner[None])
            if moved[end]:
                flange.append(np.stack([corner, Q[end], P[end]])[None])
    return np.concatenate(line), np.concatenate(flange)


def seam_gap(a: tuple, b: tuple, lo: float, hi: float) -> float:
    """Largest vertical distance (metres) between two side profiles over [lo, hi] (world metres along the seam);
    both are linear between their vertices, so it is taken at every vertex of either and at the ends."""
    if not (len(a[0]) and len(b[0])) or hi < lo:
        return 0.0
    s = np.concatenate([a[0], b[0], [lo, hi]])
    s = s[(s >= lo) & (s <= hi)]
    return float(np.max(np.abs(np.interp(s, *a) - np.interp(s, *b)), initial=0.0))


def skirt_arrays(vertices: np.ndarray, sides: list[np.ndarray], extent) -> tuple:
    """(vertices (v, 5) float32: tile-local metres, side, lower flag; faces (f, 3) uint32; per side (first index,
    index count); per side its line (``side_skirt``)) of a tile's skirts and flanges, sides in order W, E, S, N."""
    verts, tris, ranges, lines = [], [], [], []
    base = first = 0
    for k, edges in enumerate(sides):
        line, flange = side_skirt(vertices, edges, k, extent)
        m, t = len(line), len(flange)
        block = [
            np.column_stack([pts, np.full(len(pts), k), np.full(len(pts), flag)])
            for pts, flag in ((line, 0.0), (line, 1.0), (flange.reshape(-1, 3), 0.0))
        ]
        top = base + np.arange(m - 1)
        low = top + m
        faces = [
            np.stack([top, low, low + 1], 1),
            np.stack([top, low + 1, top + 1], 1),
            base + 2 * m + np.arange(3 * t).reshape(t, 3),
        ]
        verts += block
        tris += faces
        count = 3 * sum(len(f) for f in faces)
        ranges.append((first, count))
        lines.append(line)
        base, first = base + 2 * m + 3 * t, first + count
    v = np.concatenate(verts).astype(np.float32)
    f = np.concatenate(tris).astype(np.uint32)
    return v, f, ranges, lines


class SkirtMesh:
    """One tile's skirts on the GPU (``skirt_arrays``: 20 bytes a vertex, 12 a triangle), with each side's
    profile (world metres along the side, heights in metres above the terrain origin z) and the clip rectangle
    of the tile they were made for."""

    def __init__(self, ctx, prog, vertices: np.ndarray, sides: list[np.ndarray], tile):
        h = np.asarray(tile.heights)
        extent = ((h.shape[1] - 1) * float(tile.spacing_x), (h.shape[0] - 1) * float(tile.spacing_y))
        v, f, self.ranges, lines = skirt_arrays(vertices, sides, extent)
        self.profiles = [
            (float(tile.origin[1 if k < 2 else 0]) + ln[:, 1 if k < 2 else 0], ln[:, 2]) for k, ln in enumerate(lines)
        ]
        self.top = np.array([p[1].max(initial=-np.inf) for p in self.profiles])
        self.clip = tuple(float(c) for c in tile.clip)
        self.spacing = max(float(tile.spacing_x), float(tile.spacing_y))
        self.vbo = ctx.buffer(v.tobytes() or b"\0" * 20)
        self.ibo = ctx.buffer(f.tobytes() or b"\0" * 12)
        self.vao = ctx.vertex_array(
            prog, [(self.vbo, "3f 2f", "a_pos", "a_skirt")], index_buffer=self.ibo, index_element_size=4
        )

    @property
    def nbytes(self) -> int:
        """GPU bytes: vertex buffer + index buffer."""
        return int(self.vbo.size + self.ibo.size)

    def draw(self, depths: np.ndarray) -> int:
        """Issue the sides from the first to the last with a depth > 0 (a side between them at 0 draws only its
        flange, part of the tile's own square); triangles issued."""
        on = np.flatnonzero(depths > 0)
        if not len(on):
            return 0
        first = self.ranges[on[0]][0]
        count = self.ranges[on[-1]][0] + self.ranges[on[-1]][1] - first
        if count:
            self.vao.render(vertices=count, first=first)
        return count // 3

    def release(self) -> None:
        """Free the GPU objects."""
        for o in (self.vao, self.ibo, self.vbo):
            o.release()


def overlap(a, b, side: int) -> tuple[float, float]:
    """The stretch (world metres) of the seam along side ``side`` of clip rectangle a shared with rectangle b."""
    i = (1, 3) if side < 2 else (0, 2)
    return max(a[i[0]], b[i[0]]), min(a[i[1]], b[i[1]])


class SeamDepths:
    """Each frame's skirt depths per item and side (metres), from the drawn items' skirt meshes; the gap of a pair
    of tiles is kept (tile keys and side: their meshes do not change)."""

    def __init__(self, low: float):
        self.low = float(low)  # lowest height (metres above the origin z) a surface can have
        self.gaps: dict = {}
        self.last: tuple = ((), np.zeros((0, 4)))  # the last frame's items (keys, edge levels, clips), depths

    def __call__(self, items) -> np.ndarray:
        """(B, 4) depths (metres; 0: no skirt) for (gpu, tile, selected) items, on each side facing a selected
        neighbour: the largest gap to the neighbours drawn there plus the margin, where one of them differs in level
        or in its surface along the side (same-level tiles of one grid share their border samples); to the lowest
        height when none of them is among the items; none on a tile drawn from an ancestor (clipped inside its
        mesh)."""
        frame = tuple((it[2].key, it[2].edge_deltas, it[1].clip, it[0].skirt.clip) for it in items)
        if frame == self.last[0]:
            return self.last[1]
        out = np.zeros((len(items), 4))
        mine = {it[2].key: i for i, it in enumerate(items) if it[0].skirt.clip == tuple(map(float, it[1].clip))}
        keys = set(mine)
        top = max((k.level for k in keys), default=0)
        for key, i in mine.items():
            sk, sel = items[i][0].skirt, items[i][2]
            for k, (dx, dy) in enumerate(STEPS):
                if sel.edge_deltas[k] == NO_NEIGHBOUR or not len(sk.profiles[k][0]):
                    continue
                near = edge_neighbours(keys, key, dx, dy, top)
                gaps = [self.gap(items[i], k, items[mine[n]]) for n in near]
                if not near:
                    out[i, k] = sk.top[k] - min(self.low, sk.profiles[k][1].min()) + MARGIN * sk.spacing
                elif max(gaps) > 0 or any(n.level != key.level for n in near):
                    out[i, k] = max(gaps) + MARGIN * sk.spacing
        self.last = (frame, out)
        return out

    def gap(self, a, side: int, b) -> float:
        """Largest vertical distance (metres) between item a's side ``side`` and item b's opposite side."""
        key = (a[2].key, side, b[2].key)
        if key not in self.gaps:
            lo, hi = overlap(a[1].clip, b[1].clip, side)
            self.gaps[key] = seam_gap(a[0].skirt.profiles[side], b[0].skirt.profiles[side ^ 1], lo, hi)
        return self.gaps[key]
