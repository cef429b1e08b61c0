"""The raster strategies' node arrays of a virtual periodic extension (``hybrid.tiles.periodic``), served from the
source store's node arrays (``hybrid.tiles.store_nodes``) a window at a time, as the extension serves its heights.

Global node level g has nodes of s = 2^(g+1) cells, T = P / s of them a period (P the period in cells). For s <= P,
node (a, b) of the extension reads the source's node (rho(a), rho(b)): rho(a) = a mod T over the extension's grid,
0 over the padding beyond it (k periods, k not a power of two: the padded square repeats the extension's last row
and column, the source's row 0 and column 0). A node touching a seam (local index a mod T = T-1) differs from its
source node: its last row is the source's row 0, not its row P. A node's box spans the samples of its 3x3
neighbourhood, so boxes differ at local indices T-2, T-1 and 0; its saturated error depends on the errors of the
nodes ``dilate4`` reaches, one child further at each level down, which stops 2 cells short of the node's side
beyond its edges, so errors differ at T-1 and (from level 1) 0. Row 0 of the extension, and every node elsewhere,
is its source node's value exactly (bit for bit where the source's is measured). Near a seam:
- effective error, bounded: a node touching a seam has its samples and fan posts changed by at most the seam step
  there (``SeamProfiles``), and its fans are convex combinations of their posts, so its error is at most the
  source's effective error plus twice the step plus mu (16 float64 ulps of the largest height); a padding node
  repeats one row (or column) of the source's samples, where its fans deviate as the source's first node row does
  along its bottom edge, which the source's error covers. The saturation is then taken ``DEPTH`` levels down over
  the extension without end (the same pattern in every period, so the window's own rows and columns serve), below
  that as a flat bound: the largest source effective error over the 3x3 neighbourhood (the source's effective
  error of a node bounds beta^-(g - g') times the error of each level-g' node inside it) plus (2 D + mu) / beta^g,
  D the largest step along the neighbourhood's span of the seam (row and column steps added near a corner), as the
  saturation carries a finer node's change at most beta^-g times. Nodes over and next to the padding take the flat
  bound. Never below the extension's exact saturated error, and saturated itself (every tightening is a max of
  bounds over beta of the level below, the flat bound is saturated, and near-seam children lie near the seam only
  where their parent does, their neighbourhoods inside its own, their spans inside its span).
- box range: the min (max) of the source's boxes over the 3x3 neighbourhood and of the seam's samples (the source's
  row 0 or column 0) along the neighbourhood's span: every sample of the grown box is a source sample inside one
  of those source boxes, or a seam sample; and a child's boxes lie inside its parent's, as the source's do.
Levels whose nodes are larger than a period: a node's error is at most the terrain's height range H (fans interpolate
samples), so the saturated error is at most max(E, beta (H + mu)) / beta^(g - G), E the largest flat bound of the
source's top node level G; their boxes span the source's heights.
Bounds are rounded up to float32 with a little headroom (``_UP``) for the float32 rounding of the source's values.

A source whose nodes carry side codes (its nodes split on their full fans' errors: ``hybrid.tiles.sidecodes``)
keeps the combined form beside them (one error over both fans: at least every side, the level-0 diagonal terms
included). The bounds above are then taken from the combined errors, so a node near a seam holds a combined bound,
and its side codes are those of that bound (every side read as at least it); every other node is its source node,
codes included. That mix keeps the selection's rules: a node away from the seams has no child or edge neighbour's
child near one (so its saturation and the sides facing it are the source's), a node near one bounds the combined
errors of all of them over beta (which bound their sides and their side-form errors), and a source code read
against a parent whose error became a bound reads larger, never smaller.
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import TerrabenchError

from .fans import block2, dilate4
from .seams import SeamProfiles, profile_spans
from .sidecodes import holds_side_codes, side_codes_each
from .source_chunks import SourceChunks

KINDS = ("effective", "zlo", "zhi")
_UP = 1.0 + 2.0**-21  # relative headroom over float32 rounding (2^-24 per rounded value)
MAX_WHOLE_NODES = 1 << 26  # a level may be read whole (np.asarray) up to this many nodes
DEPTH = 2  # levels below a near-seam node whose bounds tighten its own (``_effective``)


def _up32(x) -> np.ndarray:
    """float32 values never below the float64 ones."""
    x = np.asarray(x, dtype=np.float64)
    y = x.astype(np.float32)
    return np.where(y < x, np.nextafter(y, np.float32(np.inf)), y)


def _nbr3(v: np.ndarray, fn) -> np.ndarray:
    """fn over each inner element's 3x3 neighbourhood of a (h + 2, w + 2) array: (h, w)."""
    h, w = v.shape[0] - 2, v.shape[1] - 2
    out = v[1:-1, 1:-1].copy()
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            out = fn(out, v[dy : dy + h, dx : dx + w])
    return out


def _run3(v: np.ndarray, fn) -> np.ndarray:
    """fn over each inner element and its two neighbours of a (w + 2,) array: (w,)."""
    return fn(fn(v[:-2], v[1:-1]), v[2:])


class PeriodicNodes:
    """The node arrays of a periodic extension: ``level(kind, g)`` gives a lazy array of global level g.

    ``source`` is the source store's group (its node arrays cover its square of P cells), ``periods`` the k
    periods a side of the extension, ``square`` the cells a side of the extension's padded square, ``beta`` the
    source's node arrays' beta, ``height_range`` the terrain's (metres).
    """

    def __init__(
        self,
        source,
        P: int,
        periods: int,
        square: int,
        profiles: SeamProfiles,
        beta: float,
        height_range: tuple[float, float],
    ):
        self.source, self.P, self.k, self.square = source, int(P), int(periods), int(square)
        self.levels, self.src_levels = int(np.log2(square)), int(np.log2(P))
        self.beta, self.profiles = float(beta), profiles
        lo, hi = (float(v) for v in height_range)
        self.mu = 16 * np.finfo(np.float64).eps * max(abs(lo), abs(hi), 1.0)
        self._spans: dict = {}
        self._top: tuple | None = None
        self.source_chunks = SourceChunks(source)
        # a source with side codes: near the seams its nodes take bounds of the combined form (one error over both
        # fans, which bounds every side) from its ``combined`` arrays, and codes from those bounds
        self.sides = holds_side_codes(source)
        self.bounds = "combined" if self.sides else "effective"
        self.kinds = KINDS + (("sides",) if self.sides else ())

    def level(self, kind: str, g: int) -> NodeLevel:
        """The lazy array of kind ``effective``, ``zlo`` or ``zhi`` (metres, float32) at global level g."""
        if kind not in self.kinds or not 0 <= g < self.levels:
            raise TerrabenchError(
                f"no periodic node array {kind!r} at level {g} (kinds {self.kinds}, levels 0..{self.levels - 1})"
            )
        return NodeLevel(self, kind, g)

    def _level_spans(self, g: int) -> dict:
        """Per source node of level g (T values): the largest seam steps and the seam samples' range along it."""
        if g not in self._spans:
            s, p = 2 << g, self.profiles
            self._spans[g] = {
                "row_step": profile_spans(p.row_step, s, np.maximum),
                "col_step": profile_spans(p.col_step, s, np.maximum),
                "row_lo": profile_spans(p.row0, s, np.minimum),
                "row_hi": profile_spans(p.row0, s, np.maximum),
                "col_lo": profile_spans(p.col0, s, np.minimum),
                "col_hi": profile_spans(p.col0, s, np.maximum),
            }
        return self._spans[g]

    def _top_values(self) -> tuple[float, float, float]:
        """(base error, zlo, zhi) of the levels above the source's: base / beta^(g - G) bounds level g's errors."""
        if self._top is None:
            G = self.src_levels - 1
            eff = float(np.asarray(self.source[f"nodes/{self.bounds}/{G}"][:, :], dtype=np.float64).max())
            zlo = float(np.asarray(self.source[f"nodes/zlo/{G}"][:, :]).min())
            zhi = float(np.asarray(self.source[f"nodes/zhi/{G}"][:, :]).max())
            step = float(self.profiles.row_step.max() + self.profiles.col_step.max())
            top = (eff + (2.0 * step + self.mu) * self.beta**-G) * _UP  # every node of level G, seams included
            self._top = (max(top, self.beta * (zhi - zlo + self.mu)), zlo, zhi)
        return self._top

    def _rho(self, a: np.ndarray, T: int, wrap: bool) -> np.ndarray:
        """The source node indices of the extension's node indices a (T nodes a period): a mod T, or 0 over the
        padding; ``wrap``: as if the extension went on without end (a mod T for every integer a)."""
        return a % T if wrap else np.where(a >= self.k * T, 0, a % T)

    def _near(self, a: np.ndarray, T: int, g: int, kind: str, wrap: bool = False) -> np.ndarray:
        """Which node indices a of level g (T nodes a period) differ from the source's node rho(a): padding nodes,
        nodes touching a seam (local T-1), and those whose reach crosses one: for errors the first node after
        a seam (g >= 1: its saturation reaches nodes touching the seam below it; the node before the seam's
        reaches 2 cells short of it), for boxes that one and the node before (a 3x3 neighbourhood)."""
        loc = a % T
        near = loc == T - 1
        if g or kind != "effective":
            near |= (loc == 0) if wrap else (loc == 0) & (a > 0)
        if kind != "effective":
            near |= loc == T - 2
        return near if wrap else near | (a >= self.k * T)

    def _read(self, kind: str, g: int, r0: int, r1: int, c0: int, c1: int, wrap):
        """Source values (float64) at the extension's nodes rows r0..r1-1, columns c0..c1-1 of level g, with the
        indices, their source nodes, and which count: indices past the square's edges are clamped and do not
        count; ``wrap=True``: every index counts, as in an extension without end; ``wrap="below"``: indices below
        0 count, wrapped (periods before the first), those past the square's far edges do not."""
        T, total = self.P >> (g + 1), self.square >> (g + 1)
        ri, ci = np.arange(r0, r1), np.arange(c0, c1)
        if wrap is True:
            rr, rc, ok_r, ok_c = ri % T, ci % T, np.ones(len(ri), bool), np.ones(len(ci), bool)
        else:
            lo = None if wrap == "below" else 0
            rr, rc = (self._rho(np.clip(i, lo, total - 1), T, False) for i in (ri, ci))
            ok_r, ok_c = ((i < total) & ((i >= 0) | (lo is None)) for i in (ri, ci))
        vals = self.source_chunks.gather(kind, g, rr, rc).astype(np.float64)
        return vals, ri, ci, rr, rc, ok_r, ok_c

    def _flat(self, g: int, r0: int, r1: int, c0: int, c1: int, wrap) -> np.ndarray:
        """Effective error bounds (float64 metres) of level-g nodes rows r0..r1-1, columns c0..c1-1 (-inf where they
        do not count, as ``_read``): the source's value, or near a seam the largest over the 3x3 neighbourhood
        plus (2 D + mu) / beta^g."""
        T = self.P >> (g + 1)
        vals, ri, ci, rr, rc, ok_r, ok_c = self._read(self.bounds, g, r0 - 1, r1 + 1, c0 - 1, c1 + 1, wrap)
        vals[~ok_r, :] = -np.inf
        vals[:, ~ok_c] = -np.inf
        near_r, near_c = (self._near(i[1:-1], T, g, "effective", wrap is True) for i in (ri, ci))
        sp = self._level_spans(g)
        step_r = np.where(ok_c, sp["row_step"][rc], 0.0)  # along the columns of a row seam
        step_c = np.where(ok_r, sp["col_step"][rr], 0.0)
        d = np.where(near_r[:, None], _run3(step_r, np.maximum)[None, :], 0.0) + np.where(
            near_c[None, :], _run3(step_c, np.maximum)[:, None], 0.0
        )
        bound = _nbr3(vals, np.maximum) + (2.0 * d + self.mu) * self.beta**-g
        out = np.where(near_r[:, None] | near_c[None, :], bound, vals[1:-1, 1:-1])
        out[~ok_r[1:-1], :] = -np.inf
        out[:, ~ok_c[1:-1]] = -np.inf
        return out

    def _effective(self, g: int, r0: int, r1: int, c0: int, c1: int, depth: int) -> np.ndarray:
        """As ``_flat`` over the extension without end, tightened ``depth`` levels down: near a seam, the larger of
        the node's own error bound (the source's, plus twice the seam step along it where it touches a seam) and its
        children's and their edge neighbours' bounds over beta, as the saturation makes them."""
        if g and not depth:
            return self._flat(g, r0, r1, c0, c1, True)
        T = self.P >> (g + 1)
        vals, ri, ci, rr, rc, _, _ = self._read(self.bounds, g, r0, r1, c0, c1, True)
        near_r, near_c = (self._near(i, T, g, "effective", True) for i in (ri, ci))
        sp = self._level_spans(g)
        seam_r, seam_c = ri % T == T - 1, ci % T == T - 1  # touching a row / column seam
        step = np.where(seam_r[:, None], sp["row_step"][rc][None, :], 0.0) + np.where(
            seam_c[None, :], sp["col_step"][rr][:, None], 0.0
        )
        bound = vals + 2.0 * step + self.mu
        if g:
            kids = self._effective(g - 1, 2 * r0 - 1, 2 * r1 + 1, 2 * c0 - 1, 2 * c1 + 1, depth - 1)
            bound = np.maximum(bound, block2(dilate4(kids)[1:-1, 1:-1], np.max) / self.beta)
        return np.where(near_r[:, None] | near_c[None, :], bound, vals)

    def _effective_window(self, g: int, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        """Effective errors (float32 metres) of a window of level g (s <= P): the source's away from the seams; near
        them ``_effective`` of the extension without end (the same for every period: rows T-1 and 0 of a period
        along the window's columns, and the same columns along its rows); ``_flat`` over and next to the padding,
        whose nodes that pattern does not describe."""
        T = self.P >> (g + 1)
        ri, ci = np.arange(r0, r1), np.arange(c0, c1)
        out = self.source_chunks.gather("effective", g, self._rho(ri, T, False), self._rho(ci, T, False))
        near_r, near_c = self._near(ri, T, g, "effective"), self._near(ci, T, g, "effective")
        locs = [T - 1, T] if g else [T - 1]  # near a seam: local T-1, and 0 from level 1
        if near_c.any():
            across = _up32(self._effective(g, r0, r1, locs[0], locs[-1] + 1, DEPTH) * _UP)
            for i, t in enumerate(locs):
                at = (ci % T == t % T) & near_c
                out[:, at] = across[:, i : i + 1]
        if near_r.any():
            along = _up32(self._effective(g, locs[0], locs[-1] + 1, c0, c1, DEPTH) * _UP)
            for i, t in enumerate(locs):
                at = (ri % T == t % T) & near_r
                out[at, :] = along[i]
        total = self.square >> (g + 1)
        if self.k * T < total:
            pad_r, pad_c = ri >= self.k * T - 1, ci >= self.k * T - 1
            if pad_r.any() or pad_c.any():
                flat = _up32(self._flat(g, r0, r1, c0, c1, "below") * _UP)
                out = np.where(pad_r[:, None] | pad_c[None, :], flat, out)
        return out

    def _near_window(self, g: int, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        """Which nodes of a window of level g (s <= P) ``_effective_window`` gives bounds, not the source's value."""
        T, total = self.P >> (g + 1), self.square >> (g + 1)
        ri, ci = np.arange(r0, r1), np.arange(c0, c1)
        near = self._near(ri, T, g, "effective")[:, None] | self._near(ci, T, g, "effective")[None, :]
        if self.k * T < total:
            near |= (ri >= self.k * T - 1)[:, None] | (ci >= self.k * T - 1)[None, :]
        return near

    def _codes_window(self, g: int, r0: int, r1: int, c0: int, c1: int, shape) -> np.ndarray:
        """Side codes (``hybrid.tiles.sidecodes``) of a window of level g: the source's where the node is the
        source's, else codes of the node's own error bound (the combined form's: at least every side error) against
        its parent's served error; a source code read against a parent whose error became a bound reads larger."""
        if not shape[0] or not shape[1]:
            return np.zeros(shape, np.float32)
        near = None
        if g < self.src_levels:
            near = self._near_window(g, r0, r1, c0, c1)
            T = self.P >> (g + 1)
            src = self.source_chunks.gather(
                "sides",
                g,
                self._rho(np.arange(r0, r1), T, False),
                self._rho(np.arange(c0, c1), T, False),
            )
            if not near.any():
                return src
        own = self.window("effective", g, r0, r1, c0, c1)
        parent = None
        if g + 1 < self.levels:
            pr0, pc0 = r0 // 2, c0 // 2
            p = self.window("effective", g + 1, pr0, (r1 - 1) // 2 + 1, pc0, (c1 - 1) // 2 + 1)
            parent = p[np.ix_(np.arange(r0, r1) // 2 - pr0, np.arange(c0, c1) // 2 - pc0)]
        coded = side_codes_each(np.broadcast_to(own, (4,) + own.shape), own, parent)
        return coded if near is None else np.where(near, coded, src)

    def window(self, kind: str, g: int, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        """Nodes rows r0..r1-1, columns c0..c1-1 of a level (float32, metres)."""
        shape = (max(r1 - r0, 0), max(c1 - c0, 0))
        if kind == "sides":
            return self._codes_window(g, r0, r1, c0, c1, shape)
        if g >= self.src_levels:
            base, zlo, zhi = self._top_values()
            value = {"zlo": zlo, "zhi": zhi}.get(kind)
            if value is None:
                value = float(_up32(base * self.beta ** -(g - self.src_levels + 1) * _UP))
            return np.full(shape, value, np.float32)
        if not shape[0] or not shape[1]:
            return np.zeros(shape, np.float32)
        if kind == "effective":
            return self._effective_window(g, r0, r1, c0, c1)
        T = self.P >> (g + 1)
        fn, side = (np.minimum, "lo") if kind == "zlo" else (np.maximum, "hi")
        vals, ri, ci, rr, rc, ok_r, ok_c = self._read(kind, g, r0 - 1, r1 + 1, c0 - 1, c1 + 1, False)
        out = vals[1:-1, 1:-1].astype(np.float32)
        near_r, near_c = self._near(ri[1:-1], T, g, kind), self._near(ci[1:-1], T, g, kind)
        if not (near_r.any() or near_c.any()):
            return out
        fill = np.inf if kind == "zlo" else -np.inf
        vals[~ok_r, :] = fill
        vals[:, ~ok_c] = fill
        sp = self._level_spans(g)
        row = np.where(ok_c, sp[f"row_{side}"][rc], fill)  # a row seam's samples along the columns
        col = np.where(ok_r, sp[f"col_{side}"][rr], fill)
        m = fn(_nbr3(vals, fn), np.where(near_r[:, None], _run3(row, fn)[None, :], fill))
        m = fn(m, np.where(near_c[None, :], _run3(col, fn)[:, None], fill))
        return np.where(near_r[:, None] | near_c[None, :], m.astype(np.float32), out)  # min/max of float32: exact


def _range(index, n: int) -> tuple[int, int, bool]:
    """(start, stop, is a slice) of an index along an axis of n elements: a slice of step 1 or an integer."""
    if isinstance(index, slice):
        start, stop, step = index.indices(n)
        if step != 1:
            raise TerrabenchError(f"periodic node arrays take slices of step 1, got {index!r}")
        return start, max(stop, start), True
    if isinstance(index, (int, np.integer)) and not isinstance(index, bool):
        i = int(index) + (n if index < 0 else 0)
        if not 0 <= i < n:
            raise TerrabenchError(f"node index {index} outside 0..{n - 1}")
        return i, i + 1, False
    raise TerrabenchError(f"periodic node arrays take slices and integers, got {index!r}")


class NodeLevel:
    """One global level's node array of a periodic extension (float32, metres; row from the south): ``shape`` and
    slicing as a numpy or Zarr array, each slice computed from the source's arrays, never the whole level."""

    def __init__(self, nodes: PeriodicNodes, kind: str, g: int):
        self.nodes, self.kind, self.g = nodes, kind, int(g)
        total = nodes.square >> (g + 1)
        self.shape, self.dtype, self.ndim = (total, total), np.dtype(np.float32), 2

    def __getitem__(self, index):
        rows, cols = index if isinstance(index, tuple) else (index, slice(None))
        r0, r1, rs = _range(rows, self.shape[0])
        c0, c1, cs = _range(cols, self.shape[1])
        out = self.nodes.window(self.kind, self.g, r0, r1, c0, c1)
        return out if rs and cs else out[0] if cs else out[:, 0] if rs else out[0, 0]

    def __array__(self, dtype=None, copy=None):
        if self.shape[0] * self.shape[1] > MAX_WHOLE_NODES:
            raise TerrabenchError(
                f"periodic node level {self.g} has {self.shape[0]}² nodes; read it a window at a "
                f"time (whole up to {MAX_WHOLE_NODES})"
            )
        a = self[:, :]
        return a if dtype is None else a.astype(dtype)
