"""Experiment specs (TOML): which datasets, flights, policies, tau values, sizes and modes to pair.

    name = "puget-default"
    datasets = ["puget"]              # bundled names, files, tile stores, STORE@periodicSIZE, or tables (below)
    dataset_size = 0                  # samples a side for synthetic data / crop of puget (0 = as is)
    flights = ["flyover", "orbit"]    # presets or .json/.csv flight files
    frames = 12
    policies = ["raster", "raycast", "hybrid", "heuristic", "oracle"]
    taus = [0.6667]
    sizes = ["640x360"]
    reconstructions = ["triangles"]   # ray-cast surface reconstructions
    full_res = ["lean"]               # raster full-resolution rules: "lean", "exact" (the reference's cells)
    adapt = true                      # the hybrid refits its cost model from the frames it draws (false: frozen)
    reuse_choice = 1                  # the hybrid plans every frame (each frame's tiles and features in the tables,
                                      # resumable frame by frame); N > 1 reuses a clear pure choice for up to N - 1
                                      # frames between full plans, as an application's renderer does by default
    start_models = ["device"]         # the hybrid's starting cost model: "device" (this GL renderer's, as loaded),
                                      # "fallback" (the shipped uncalibrated one): one hybrid config each
    repeats = 3                       # timed repeats a frame, at least 3 (median kept, spread = noise)
    seeds = [0]
    tile_size = 256
    supersample = 2                   # reference colour supersampling
    flip = true                       # compute mean FLIP (slower)
    image_frames = [0]                # frames whose images are kept for the report
    video = false                     # keep every frame's image for `terrabench report --video`
    accuracy = true                   # false: no reference image, timing only (no accuracy columns, no images)

A dataset entry can be a table giving a file and how to load it (every key but ``path`` optional), inline
(``datasets = ["puget", {path = "dem.tif", spacing = 30.0}]``, one line) or, after every other key, as

    [[datasets]]
    path = "dem.tif"
    name = "rainier"                  # its label in runs and reports (default: the path)
    spacing = [25.0, 30.0]            # ground metres: one number, or [east-west, north-south]
    vertical_scale = 0.1              # metres per stored unit
    crs = "EPSG:32610"                # overrides the file's CRS
    crop = {row = 0, col = 0, rows = 513, cols = 513}   # samples, rows as stored in the file
    credit = "USGS 3DEP 1/3 arc-second DEM"              # the report's line for these data

Relative paths are relative to the spec file's folder. ``STORE@periodicSIZE`` is the virtual periodic extension
of a tile store to SIZE samples a side, STORE a store's folder or ``puget`` (its store prepared once into the
cache at the spec's tile size: ``experiments.store_datasets``); e.g. ``puget@periodic16385``.
"""

from __future__ import annotations

import itertools
import json
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import get_args, get_type_hints

from hybrid.contract import DEFAULT_FULL_RES, PRIOR_FULL_RES
from hybrid.errors import TerrabenchError
from hybrid.strategies import adapting_policies, policies_taking
from hybrid.terrain.sources import TerrainSource

from .run_config import Config
from .spec_datasets import check_dataset_entry, dataset_label, terrain_source
from .spec_keys import START_MODELS, checked_list, list_keys, scalar_keys
from .stress_spec import parse_stress_spec


@dataclass
class Spec:
    """A parsed, checked experiment spec."""

    name: str
    datasets: list[str | dict] = field(default_factory=lambda: ["puget"])
    dataset_size: int = 0
    flights: list[str] = field(default_factory=lambda: ["flyover"])
    frames: int = 12
    policies: list[str] = field(default_factory=lambda: ["raster", "raycast", "hybrid"])
    taus: list[float] = field(default_factory=lambda: [2 / 3])
    sizes: list[str] = field(default_factory=lambda: ["640x360"])
    reconstructions: list[str] = field(default_factory=lambda: ["triangles"])
    full_res: list[str] = field(default_factory=lambda: [DEFAULT_FULL_RES])
    repeats: int = 3
    seeds: list[int] = field(default_factory=lambda: [0])
    tile_size: int = 256
    supersample: int = 2
    flip: bool = True
    image_frames: list[int] = field(default_factory=lambda: [0])
    video: bool = False
    accuracy: bool = True
    gpu_budget_mib: int = 256
    upload_budget_ms: float | None = None
    adapt: bool = True
    reuse_choice: int = 1
    start_models: list[str] = field(default_factory=lambda: ["device"])

    def configs(self) -> list[Config]:
        """Every combination, one Config each, with a stable id; frames of one (dataset, seed, flight, size) are
        paired."""
        out = []
        labels = [dataset_label(d) for d in self.datasets]
        casting, tilelets, adapting = (
            policies_taking("reconstruction"),
            policies_taking("full_res"),
            adapting_policies(),
        )
        for ds, seed, fl, size, tau, rec, fr, pol, sm in itertools.product(
            labels,
            self.seeds,
            self.flights,
            self.sizes,
            self.taus,
            self.reconstructions,
            self.full_res,
            self.policies,
            self.start_models,
        ):
            if pol not in casting and rec != self.reconstructions[0]:
                continue  # reconstruction only matters where rays are cast
            if pol not in tilelets and fr != self.full_res[0]:
                continue  # the full-resolution rule only where tilelets are drawn
            if pol == "reference" and tau != self.taus[0]:
                continue
            if pol not in adapting and sm != self.start_models[0]:
                continue  # only the hybrid reads a cost model as it goes
            fr = fr if pol in tilelets else PRIOR_FULL_RES
            sm = sm if pol in adapting else START_MODELS[0]
            cid = (
                f"{Path(str(ds)).stem}-s{seed}-{Path(str(fl)).stem}-{size}-tau{tau:.4g}-{rec}-{pol}"
                + ("" if fr == PRIOR_FULL_RES else f"-{fr}")
                + ("" if sm == START_MODELS[0] else f"-from-{sm}")
            )
            out.append(Config(cid, ds, seed, fl, size, tau, rec, fr, pol, sm))
        return out

    def source(self, label: str) -> TerrainSource:
        """The terrain a dataset label (as in configs()) names, with its loader options and credit."""
        for entry in self.datasets:
            if dataset_label(entry) == label:
                return terrain_source(entry)
        raise TerrabenchError(f"spec {self.name!r} has no dataset {label!r}")

    def terrain(self, label: str, seed: int):
        """The HeightField a dataset label names (a tile store's periodic extension stays on disk)."""
        from .store_datasets import open_periodic_dataset, split_periodic

        source = self.source(label)
        if split_periodic(source.dataset):
            return open_periodic_dataset(source.dataset, self.tile_size)
        return source.load(size=self.dataset_size or None, seed=seed)

    def to_dict(self) -> dict:
        """Plain form."""
        return asdict(self)

    def same_as(self, stored: dict) -> bool:
        """Whether a stored plain form (a run folder's spec.json) is this spec; keys it lacks (added to specs since
        it was written) count as what runs did before them (``BEFORE_KEYS``), else as their defaults."""
        here = json.loads(json.dumps(self.to_dict()))
        defaults = json.loads(json.dumps(Spec(name=self.name).to_dict()))
        return {**defaults, **BEFORE_KEYS, **stored} == here


BEFORE_KEYS = {"full_res": [PRIOR_FULL_RES], "adapt": False}
"""Spec keys added since runs were first written, with what those runs did: a spec.json without the key."""


def parse_spec(text: str, source: str = "spec", base: Path | None = None, overrides: dict | None = None):
    """Parse and check TOML text (a paired-flight Spec, a StressSpec when kind = "stress", an EditSpec when "edit").

    ``base`` is the folder relative dataset paths are taken from (the spec file's); None keeps them as given.
    ``overrides`` (the command line's ``frames``, ``sizes``) replace the text's keys before the checks.
    """
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise TerrabenchError(f"{source}: not valid TOML ({exc})") from None
    kind = d.pop("kind", "flights")
    d = _overridden(d, overrides or {}, kind, source)
    if kind == "stress":
        return parse_stress_spec(d, source)
    if kind == "edit":
        from .edit_spec import parse_edit_spec

        return parse_edit_spec(d, source, base)
    if kind != "flights":
        raise TerrabenchError(f"{source}: kind must be 'flights' (default), 'stress' or 'edit', got {kind!r}")
    known = set(Spec.__dataclass_fields__)
    unknown = set(d) - known
    if unknown:
        raise TerrabenchError(f"{source}: unknown keys {sorted(unknown)}; known: {sorted(known)}")
    kw = {"name": d.get("name", Path(source).stem)}
    if not isinstance(kw["name"], str) or not kw["name"] or any(c in kw["name"] for c in "/\\ "):
        raise TerrabenchError(f"{source}: name must be a non-empty word without slashes or spaces, got {kw['name']!r}")
    if "datasets" in d:
        kw["datasets"] = _datasets(d["datasets"], source, base)
    types = get_type_hints(Spec)  # each key's type, as the dataclass declares it
    for key, check in list_keys(source):
        kind = get_args(types[key])[0]  # a list key's entry type; integers are numbers too
        v = checked_list(d, key, (int, float) if kind is float else kind, check)
        if v is not None:
            kw[key] = [float(x) for x in v] if kind is float else v
    kw.update(scalar_keys(d, source, flags=[k for k, t in types.items() if t is bool]))
    return _checked(Spec(**kw), source)


def _datasets(v, source: str, base: Path | None) -> list:
    """The spec's dataset entries, checked, with distinct labels."""
    if not isinstance(v, list) or not v:
        raise TerrabenchError(f"{source}: 'datasets' must be a non-empty list, got {v!r}")
    entries = [check_dataset_entry(e, source, base) for e in v]
    labels = [dataset_label(e) for e in entries]
    twice = sorted({label for label in labels if labels.count(label) > 1})
    if twice:
        raise TerrabenchError(f"{source}: datasets {twice} appear twice; give each a distinct 'name'")
    return entries


def _checked(spec: Spec, source: str) -> Spec:
    """The spec, refused by name where its keys disagree with each other."""
    if spec.video and not spec.accuracy:
        raise TerrabenchError(
            f"{source}: 'video' shows each method beside the reference, which accuracy = false "
            "leaves out; drop one of them"
        )
    bad = [f for f in spec.image_frames if not (0 <= f < spec.frames)]
    if bad:
        raise TerrabenchError(f"{source}: image_frames {bad} outside [0, {spec.frames - 1}]")
    return spec


def _overridden(d: dict, overrides: dict, kind: str, source: str) -> dict:
    """A spec's keys with overrides in place; fewer frames keep the image frames that still fall inside them."""
    if overrides and kind == "stress":
        raise TerrabenchError(f"{source}: a stress spec takes no {', '.join(sorted(overrides))} override")
    out = {**d, **overrides}
    if "frames" in overrides and "image_frames" not in overrides:
        kept = [f for f in d.get("image_frames", [0]) if isinstance(f, int) and 0 <= f < overrides["frames"]]
        out["image_frames"] = kept or [0]
    return out


BUNDLED = {
    "default": "default.toml",
    "tiny": "tiny.toml",
    "stress": "stress.toml",
    "full-res": "full-res.toml",
    "gpu": "gpu.toml",
    "edit": "edit.toml",
}


def load_spec(path, overrides: dict | None = None) -> Spec:
    """Read and check a spec file, or a bundled spec by name (default, tiny, stress, full-res, gpu, edit), with
    ``overrides`` of its keys (parse_spec)."""
    if str(path) in BUNDLED:
        from importlib import resources

        return parse_spec(
            (resources.files("experiments") / BUNDLED[str(path)]).read_text(), str(path), overrides=overrides
        )
    p = Path(path)
    if not p.is_file():
        raise TerrabenchError(f"{path}: no such spec file")
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise TerrabenchError(f"{path}: cannot read spec ({exc})") from None
    return parse_spec(text, str(p), p.resolve().parent, overrides)
