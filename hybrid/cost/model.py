"""The per-tile cost model: predicted milliseconds of each strategy from features known before drawing.

One linear model with non-negative coefficients per candidate strategy, simple enough to print and explain:

    raster_ms    = r0 + r_tri * triangles + r_vis * triangles * visible + r_px * pixels + r_hit * surface_pixels
    raster_gs_ms = the same terms with their own coefficients (the geometry-shader path)
    raycast_ms   = c0 + c_px * pixels + c_hit * surface_pixels + c_step * pixels * log2(1 + slab_cells)

per tile, plus each strategy's per-frame overhead (state setup, the raster paths' leaf-selection dispatches,
the ray caster's pre-pass target and counters) paid once when any tile uses it, and a mixed frame's own overhead
paid once when more than one strategy is used (what a mixed frame costs beyond its tiles and strategies: meant
for the copy of the raster pass's depth that rays stop at, skirts and switching passes, not timed apart):

    frame_ms = sum over strategies used of overhead_s + [more than one used] * mix_overhead + sum of tiles

``terrabench calibrate`` times whole frames on this device, pure and with tiles assigned to the strategies at
random, and the frames' tiles one call each, and fits the coefficients, the per-frame overheads and a per-call
overhead to both together (``hybrid.cost.fit.fit_frames``), then
saves the model keyed by the GL renderer string. ``load_cost_model`` finds it again: the user's file ($TERRABENCH_COSTS or
~/.config/terrabench/costs.json), then the defaults shipped in hybrid/cost/costs_default.json; in either, the
renderer string itself or else the longest key contained in it, ignoring case ('llvmpipe', 'NVIDIA H200').
"""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from hybrid.atomic import write_json
from hybrid.contract import FULL_RES, PRIOR_FULL_RES
from hybrid.cost.features import TileFeatures
from hybrid.errors import TerrabenchError

RASTER_TERMS = ("const", "triangles", "visible_triangles", "pixels", "surface_pixels")
"""The raster strategies' terms. Fragments follow the surface's screen area (surface_pixels) more than the box's
(pixels), which seen at a grazing angle is mostly air: on one llvmpipe calibration of Puget fitted both ways (8
hold-out draws each) the term took the held-out frame error from 9.8 to 7.8 % and the raster per-tile error from
21.6 to 18.0 % (raster_gs 19.2 to 16.6 %), and the pure raster frames' median predicted / measured from 0.75 to
0.83 on the orbit (surface 0.9 of the box, median tile) and 1.14 to 1.03 on the dolly (0.1)."""
TERMS = {
    "raster": RASTER_TERMS,
    "raster_gs": RASTER_TERMS,
    "raycast": ("const", "pixels", "surface_pixels", "pixel_steps"),
}
"""The model's terms per candidate strategy (hybrid.strategies.candidates())."""


ALL_TERMS = ("const", "triangles", "visible_triangles", "pixels", "surface_pixels", "pixel_steps")
_TERM_INDEX = {s: [ALL_TERMS.index(t) for t in terms] for s, terms in TERMS.items()}


def all_term_values(f) -> np.ndarray:
    """Every term of ``ALL_TERMS`` for one tile (a ``TileFeatures``: shape (6,)) or many (a dict of (B,) feature
    columns as from ``hybrid.cost.features.feature_columns``, all of one shape: shape (B, 6))."""
    g = f if isinstance(f, dict) else vars(f)
    tri, px = np.asarray(g["triangles"], dtype=np.float64), np.asarray(g["pixels"], dtype=np.float64)
    return np.stack(
        [
            np.ones_like(px),
            tri,
            tri * g["visible"],
            px,
            np.asarray(g["surface_pixels"], dtype=np.float64),
            px * np.log2(1.0 + np.asarray(g["slab_cells"], dtype=np.float64)),
        ],
        axis=-1,
    )


def term_values(f, strategy: str) -> np.ndarray:
    """The model's input terms of one strategy for one tile (shape (4,)) or many (shape (B, 4)), as
    ``all_term_values``."""
    if strategy not in TERMS:
        raise TerrabenchError(f"unknown strategy {strategy!r} for the cost model; choose one of {', '.join(TERMS)}")
    return all_term_values(f)[..., _TERM_INDEX[strategy]]


@dataclass
class CostModel:
    """Coefficients (milliseconds per unit of each term, ``coefficients[strategy][term]``) per candidate strategy,
    and how well they fit: ``fit_error`` the held-out median relative error of frame times (frames using the
    strategy) when fitted on ``frames`` whole frames, else of per-tile times.

    A strategy without coefficients (``raster_gs`` in a model calibrated before the geometry-shader path was a
    candidate) is never chosen.
    """

    renderer: str
    coefficients: dict[str, dict[str, float]]
    fit_error: dict = field(default_factory=dict)
    tiles: int = 0
    source: str = ""
    overhead: dict = field(default_factory=lambda: dict.fromkeys(TERMS, 0.0))
    frames: int = 0  # whole frames fitted (0: fitted on per-tile times)
    tile_error: dict = field(default_factory=dict)  # held-out per-tile error against tiles timed a call each
    call_overhead: dict = field(default_factory=dict)  # ms one tile drawn as its own call adds (fitted with the tiles)
    mix_error: float = 0.0  # held-out median relative error of the frames that use more than one strategy
    mix_overhead: float = 0.0  # ms a frame that uses more than one strategy adds (fitted with the frames)
    full_res: str = PRIOR_FULL_RES  # the full-resolution rule its raster frames were drawn by
    adapted_frames: int = 0  # frames it learned from online after it was loaded (hybrid.cost.online)
    online_fit: int = 0  # the version of the online fit that learned it (ONLINE_FIT_VERSION), 0: not learned online

    @property
    def candidates(self) -> tuple[str, ...]:
        """The strategies this model has coefficients for, in TERMS order."""
        return tuple(s for s in TERMS if self.coefficients.get(s))

    def frame_ms(self, tile_costs: list[float] | np.ndarray, strategies: set) -> float:
        """Predicted frame time (ms): the tiles' costs plus the overhead of each strategy used, and the mixed
        frame's own overhead where more than one is used."""
        mixed = self.mix_overhead if len(strategies) > 1 else 0.0
        tiles = tile_costs.sum() if isinstance(tile_costs, np.ndarray) else sum(tile_costs)
        return float(tiles + sum(self.overhead.get(s, 0.0) for s in strategies) + mixed)

    def predict(self, f: TileFeatures) -> dict[str, float]:
        """Predicted milliseconds each strategy adds to a frame for one tile (overhead not included)."""
        return {s: float(v) for s, v in self.predict_columns(f).items()}

    def predict_columns(self, columns) -> dict[str, np.ndarray]:
        """Predicted milliseconds of each strategy for many tiles at once, from feature columns ((B,) arrays); a
        raster strategy's is NaN where the triangles are unknown (NaN), the ray caster's is not."""
        return dict(zip(self.candidates, self.predict_table(columns)))

    def predict_table(self, columns, unknown: float = np.nan) -> np.ndarray:
        """(candidates, B) predicted ms, rows in ``candidates`` order, from feature columns ((B,) arrays, or one
        ``TileFeatures``: (candidates,)); the raster rows are ``unknown`` where the triangles are NaN."""
        return self.predict_terms(all_term_values(columns), unknown)

    def predict_terms(self, terms: np.ndarray, unknown: float = np.nan) -> np.ndarray:
        """``predict_table`` from the columns' term values (``all_term_values``: (B, terms) or (terms,))."""
        shape, terms = terms.shape[:-1], terms.reshape(-1, len(ALL_TERMS))
        cands = self.candidates
        coef = self.coefficient_table()
        nan = np.isnan(terms[:, 1])
        unknown_any = bool(nan.any())
        if unknown_any:
            terms = terms.copy()
            terms[nan, 1:3] = 0.0  # triangle terms only: the ray caster's prediction stays known
        table = coef @ terms.T
        if unknown_any:
            table[np.ix_(["triangles" in TERMS[s] for s in cands], nan)] = unknown
        return table.reshape(len(cands), *shape)

    def coefficient_table(self) -> np.ndarray:
        """(candidates, len(ALL_TERMS)) coefficients (ms per unit of each term, 0 where a strategy has no such
        term), rows in ``candidates`` order; read-only."""

        def build():
            cands = self.candidates
            rows = [[self.coefficients[s].get(t, 0.0) if t in TERMS[s] else 0.0 for t in ALL_TERMS] for s in cands]
            out = np.array(rows, dtype=np.float64).reshape(len(cands), len(ALL_TERMS))
            out.setflags(write=False)
            return out

        return self._memo("coef", build)

    def uses_triangles(self) -> np.ndarray:
        """(candidates,) whether each candidate's prediction needs the tile's triangles (a raster strategy)."""
        return np.array(["triangles" in TERMS[s] for s in self.candidates], dtype=np.bool_)

    def choice_arrays(self, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per strategy of ``names`` (S,): per-frame overhead (ms), held-out frame error and per-tile error (the
        frame error where no tile error was fitted), as the choice reads them; read-only."""

        def build():
            out = (
                np.array([self.overhead.get(n, 0.0) for n in names], dtype=np.float64),
                np.array([self.fit_error.get(n, 0.0) for n in names], dtype=np.float64),
                np.array([self.tile_error.get(n, self.fit_error.get(n, 0.0)) for n in names], dtype=np.float64),
            )
            for a in out:
                a.setflags(write=False)
            return out

        return self._memo(("choice", tuple(names)), build)

    def _memo(self, key, build):
        """``build()`` made once while the model's coefficient and error dicts stay as they were (compared with the
        copies kept beside it at every call: a dict edited in place makes it anew)."""
        now = (*self.coefficients.values(), self.overhead, self.fit_error, self.tile_error)
        memo = self.__dict__.setdefault("_memos", {})
        hit = memo.get(key)
        if hit is None or hit[0] != now:
            hit = memo[key] = (tuple(dict(d) for d in now), build())
        return hit[1]

    def explain(self) -> str:
        """The formulas with their coefficients, and the held-out error."""

        def fmt(s):
            c = self.coefficients[s]
            parts = [f"{c['const']:.4g}"] + [f"{c[t]:.4g}*{t}" for t in TERMS[s][1:]]
            return f"{s:9s} ms = " + " + ".join(parts)

        lines = [
            f"cost model for {self.renderer} ({self.source or 'unsaved'}, {self.tiles} tiles)",
            *(fmt(s) for s in self.candidates),
            "  pixel_steps = pixels * log2(1 + slab_cells); visible_triangles = triangles * visible",
            "  per-frame overhead: "
            + ", ".join(f"{s} {self.overhead.get(s, 0):.3g} ms" for s in self.candidates)
            + f"; a frame mixing strategies adds {self.mix_overhead:.3g} ms",
            f"  raster frames drawn with full_res {self.full_res!r}",
        ]
        if self.adapted_frames:
            lines.append(f"  adapted online over {self.adapted_frames} frames")
        if "raster_gs" not in self.candidates:
            lines.append("  raster_gs not calibrated: never chosen")
        what = f"of {self.frames} frames' times" if self.frames else "per tile"
        for s, e in self.fit_error.items():
            lines.append(f"  held-out median |relative error| {what} using {s}: {100 * e:.1f} %")
        if self.mix_error:
            lines.append(
                f"  held-out median |relative error| of mixed frames (more than one strategy): "
                f"{100 * self.mix_error:.1f} %"
            )
        if self.call_overhead:
            lines.append(
                "  per-call overhead of a tile drawn as its own call: "
                + ", ".join(f"{s} {v:.3g} ms" for s, v in self.call_overhead.items())
            )
        for s, e in self.tile_error.items():
            lines.append(
                f"  held-out median |relative error| per tile against tiles timed one call each (with the "
                f"call's overhead) {s}: {100 * e:.1f} %"
            )
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return asdict(self)


def user_costs_path() -> Path:
    """Where calibrated models are saved: $TERRABENCH_COSTS or ~/.config/terrabench/costs.json."""
    env = os.environ.get("TERRABENCH_COSTS")
    return Path(env) if env else Path.home() / ".config" / "terrabench" / "costs.json"


def read_costs_file(path: Path | None = None) -> dict:
    """The saved models of a costs file (default the user's), keyed by renderer; {} when there is none."""
    path = Path(path) if path else user_costs_path()
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise TerrabenchError(f"{path}: costs file is not valid JSON; fix or move it away") from None
    except OSError as exc:
        raise TerrabenchError(f"{path}: cannot read costs file ({exc.strerror or exc})") from None
    if not isinstance(data, dict) or not all(isinstance(k, str) and isinstance(v, dict) for k, v in data.items()):
        raise TerrabenchError(
            f"{path}: not a terrabench costs file (a JSON object of cost models keyed by GL "
            "renderer); fix or move it away"
        )
    return data


LEARNED = "learned online"
"""The costs file's section of models learned online, by GL renderer: apart from the calibrated models (the file's
other keys), so that learning never overwrites a user's calibration."""


def save_cost_model(model: CostModel, path: Path | None = None) -> Path:
    """Add or replace the model (keyed by its renderer string) in the costs file, in the ``LEARNED`` section when
    it was learned online; returns the path."""
    path = Path(path) if path else user_costs_path()
    data = read_costs_file(path)
    d = model.to_dict()
    d.pop("source", None)
    section = data.setdefault(LEARNED, {}) if model.adapted_frames else data
    section[model.renderer] = d
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TerrabenchError(f"cannot write costs file {path}: {exc.strerror or exc}") from None
    write_json(path, data)
    return path


def cost_model_from_dict(d: dict, source: str) -> CostModel:
    """A CostModel from its saved form (as in a costs file); ``source`` names where it came from."""
    try:
        coefficients = d["coefficients"] if "coefficients" in d else {s: d[s] for s in TERMS if d.get(s)}
        m = CostModel(
            d["renderer"],
            {s: dict(c) for s, c in dict(coefficients).items() if s in TERMS and c},
            fit_error=dict(d.get("fit_error", {})),
            tiles=int(d.get("tiles", 0)),
            source=source,
            overhead={**dict.fromkeys(TERMS, 0.0), **d.get("overhead", {})},
            frames=int(d.get("frames", 0)),
            tile_error=dict(d.get("tile_error", {})),
            call_overhead={s: float(v) for s, v in (d.get("call_overhead") or {}).items()},
            mix_error=float(d.get("mix_error", 0.0)),
            mix_overhead=float(d.get("mix_overhead", 0.0)),
            full_res=d.get("full_res", PRIOR_FULL_RES),
            adapted_frames=int(d.get("adapted_frames", 0)),
            online_fit=int(d.get("online_fit", 0)),
        )
        missing = [s for s in ("raster", "raycast") if s not in m.coefficients]
        if missing:
            raise KeyError(f"no coefficients for {', '.join(missing)}")
        if m.full_res not in FULL_RES:
            raise ValueError(f"full_res must be one of {', '.join(FULL_RES)}, got {m.full_res!r}")
        for s in m.candidates:
            for t in TERMS[s]:
                m.coefficients[s].setdefault(t, 0.0)  # a model saved before a term existed has it at 0
                float(m.coefficients[s][t])
        return m
    except (KeyError, TypeError, ValueError) as exc:
        raise TerrabenchError(f"{source}: malformed cost model ({exc})") from None


def matching_key(keys, renderer: str) -> str | None:
    """The key of a costs file that names this GL renderer: the renderer string itself, else the longest key
    contained in it ignoring case ('NVIDIA H200' for 'NVIDIA H200/PCIe/SSE2'); None if none does."""
    keys = [k for k in keys if k not in ("fallback", LEARNED)]
    if renderer in keys:
        return renderer
    low = renderer.lower()
    inside = [k for k in keys if k and k.lower() in low]
    return max(inside, key=len) if inside else None


ONLINE_FIT_VERSION = 4
"""The version of ``hybrid.cost.online``'s fit, saved with the models it learns: one learned by another version
is not loaded (its coefficients follow rules since changed, such as which rows exploration gathers), and the
shipped default serves instead."""


def load_cost_model(renderer: str, path: Path | None = None) -> CostModel:
    """The calibrated model for a GL renderer (matching_key): the user's file first (a model learned online by
    another version of the fit is passed over, with a warning), then the shipped defaults."""
    path = Path(path) if path else user_costs_path()
    if path.exists():
        m = costs_file_model(read_costs_file(path), renderer, str(path))
        if m is not None:
            return m
    return shipped_cost_model(renderer)


def shipped_cost_model(renderer: str) -> CostModel:
    """The model shipped with the package for a GL renderer (``matching_key``), else the uncalibrated fallback:
    what a user with no costs file gets."""
    shipped = _shipped()
    key = matching_key(shipped, renderer)
    if key is not None:
        return cost_model_from_dict(shipped[key], f"shipped default '{key}'")
    return fallback_cost_model()


_PASSED_OVER: set[tuple[str, str]] = set()  # (costs file, key) of learned models passed over, warned of once


def costs_file_model(data: dict, renderer: str, where: str) -> CostModel | None:
    """The model a costs file's ``data`` (from ``where``) holds for a GL renderer (``matching_key``): the one learned
    online, unless an earlier version of the online fit learned it (passed over, with a warning), else the
    calibrated one; None where it holds neither."""
    learned = data.get(LEARNED)
    sections: list[tuple[dict, str]] = [(learned if isinstance(learned, dict) else {}, f"{where} ({LEARNED})")]
    for section, label in [*sections, (data, where)]:
        key = matching_key(section, renderer)
        if key is None:
            continue
        m = cost_model_from_dict(section[key], label if key == renderer else f"{label} '{key}'")
        if not m.adapted_frames or m.online_fit == ONLINE_FIT_VERSION:
            return m
        if (where, key) not in _PASSED_OVER:  # said once a process: every renderer of a run loads it
            _PASSED_OVER.add((where, key))
            warnings.warn(
                f"{where}: the model for {key!r} was learned by an earlier version of the online fit; it is not "
                "used (a run learns it again, or run terrabench calibrate)",
                stacklevel=3,
            )
    return None


def _shipped() -> dict:
    return json.loads((resources.files("hybrid.cost") / "costs_default.json").read_text())


def fallback_cost_model() -> CostModel:
    """The shipped uncalibrated model, for a GL renderer nobody calibrated (an adapting hybrid learns from it)."""
    return cost_model_from_dict(_shipped()["fallback"], "shipped fallback (uncalibrated; run terrabench calibrate)")
