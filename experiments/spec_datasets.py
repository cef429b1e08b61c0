"""Dataset entries of a spec: a bundled or synthetic name, a file path, or a table of a file and its loader options.

A table's keys: ``path`` (required), ``name`` (its label in runs and reports), ``spacing`` (ground metres: one
number or [east-west, north-south]), ``vertical_scale`` (metres per stored unit), ``crs`` (overrides the file's),
``crop`` ({row, col, rows, cols} in samples, rows as stored in the file) and ``credit`` (the report's line).
A name or path ``STORE@periodicSIZE`` is a tile store's virtual periodic extension (``experiments.store_datasets``):
STORE a store's folder or ``puget``, whose store is prepared once into the cache.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hybrid.errors import TerrabenchError
from hybrid.terrain.sources import TerrainSource
from hybrid.terrain.window import Crop

from .store_datasets import BUNDLED_STORES, PERIODIC, check_periodic, split_periodic

DATASET_KEYS = ("path", "name", "spacing", "vertical_scale", "crs", "crop", "credit")
CROP_KEYS = ("row", "col", "rows", "cols")


def dataset_label(entry) -> str:
    """The label of a dataset entry in configs, tables and reports: its name, else its path or dataset name."""
    return entry if isinstance(entry, str) else entry.get("name") or entry["path"]


def terrain_source(entry) -> TerrainSource:
    """The TerrainSource of a checked dataset entry (a name or path, or a table)."""
    if isinstance(entry, str):
        return TerrainSource(entry, credit=_periodic_credit(entry))
    spacing = entry.get("spacing")
    crop = entry.get("crop")
    return TerrainSource(
        entry["path"],
        spacing=tuple(spacing) if isinstance(spacing, list) else spacing,
        vertical_scale=entry.get("vertical_scale"),
        crs=entry.get("crs"),
        crop=None if crop is None else Crop(**crop),
        credit=entry.get("credit") or _periodic_credit(entry["path"]),
        name=entry.get("name"),
    )


def _periodic_credit(path: str) -> str | None:
    """The credit of a bundled dataset's periodic extension (its data, repeated); None for any other entry."""
    from hybrid.terrain.datasets import CREDITS

    periodic = split_periodic(path)
    return CREDITS.get(periodic[0]) if periodic else None


def credit_lines(datasets: list, used) -> list[str]:
    """The credit lines of the dataset entries whose labels are in ``used`` (each once, in spec order)."""
    used = {str(u) for u in used}
    out = []
    for entry in datasets:
        if dataset_label(entry) in used:
            line = terrain_source(entry).credit_line()
            if line and line not in out:
                out.append(line)
    return out


def _positive(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0 < value < float("inf")):
        raise TerrabenchError(f"{what} must be a number > 0, got {value!r}")
    return float(value)


def _resolve(path: str, source: str, base: Path | None) -> str:
    """A dataset path resolved against base where it is a relative file (a periodic extension's store folder, its
    size kept); names as given."""
    from hybrid.terrain.datasets import NAMES

    periodic = split_periodic(path, f"{source}: ")
    if periodic:
        check_periodic(path, f"{source}: dataset {path!r}")
        store = periodic[0]
        if store in BUNDLED_STORES or base is None or Path(store).is_absolute():
            return path
        return f"{base / store}{PERIODIC}{periodic[1]}"
    file = path not in NAMES and Path(path).suffix and not Path(path).is_absolute()
    return str(base / path) if base is not None and file else path


def check_dataset_entry(entry, source: str, base: Path | None):
    """A checked dataset entry: a name or path (relative paths resolved against base), or a table of loader options."""
    from hybrid.terrain.datasets import NAMES
    from hybrid.terrain.georef import parse_crs

    if isinstance(entry, str):
        if not entry:
            raise TerrabenchError(f"{source}: a dataset entry is an empty string")
        return _resolve(entry, source, base)
    if not isinstance(entry, dict):
        raise TerrabenchError(f"{source}: 'datasets' entries must be names, paths or tables, got {entry!r}")
    unknown = set(entry) - set(DATASET_KEYS)
    if unknown:
        raise TerrabenchError(f"{source}: dataset keys {sorted(unknown)} unknown; known: {', '.join(DATASET_KEYS)}")
    path = entry.get("path")
    if not isinstance(path, str) or not path:
        raise TerrabenchError(f"{source}: a dataset table needs 'path' (a file or dataset name), got {entry!r}")
    what = f"{source}: dataset {entry.get('name') or path!r}"
    out: dict[str, Any] = {"path": _resolve(path, source, base)}  # the entry as TOML gives it, checked
    given = [k for k in ("spacing", "vertical_scale", "crs", "crop") if k in entry]
    if (path in NAMES or split_periodic(path)) and given:
        raise TerrabenchError(
            f"{what}: {', '.join(given)} apply to files, not the bundled, synthetic or stored {path!r}"
        )
    for key in ("name", "credit", "crs"):
        if key in entry:
            if not isinstance(entry[key], str) or not entry[key].strip():
                raise TerrabenchError(f"{what}: '{key}' must be a non-empty string, got {entry[key]!r}")
            out[key] = entry[key]
    if "name" in out and any(c in out["name"] for c in "/\\ "):
        raise TerrabenchError(f"{what}: 'name' must be a word without slashes or spaces, got {out['name']!r}")
    if "crs" in out:
        parse_crs(out["crs"], f"{what}: crs")
    if "spacing" in entry:
        v = entry["spacing"]
        if isinstance(v, list):
            if len(v) != 2:
                raise TerrabenchError(
                    f"{what}: 'spacing' must be one number or [east-west, north-south] metres, got {v!r}"
                )
            out["spacing"] = [_positive(x, f"{what}: 'spacing'") for x in v]
        else:
            out["spacing"] = _positive(v, f"{what}: 'spacing' (metres)")
    if "vertical_scale" in entry:
        out["vertical_scale"] = _positive(entry["vertical_scale"], f"{what}: 'vertical_scale' (metres per unit)")
    if "crop" in entry:
        c = entry["crop"]
        if not isinstance(c, dict) or set(c) != set(CROP_KEYS):
            raise TerrabenchError(f"{what}: 'crop' must be a table {{row, col, rows, cols}} in samples, got {c!r}")
        try:
            Crop(**c)
        except TerrabenchError as exc:
            raise TerrabenchError(f"{what}: {exc}") from None
        out["crop"] = {k: c[k] for k in CROP_KEYS}
    return out


def check_dataset_paths(datasets: list, source: str) -> None:
    """Refuse, naming it, a dataset entry whose file or store folder is missing or unreadable (a symlink loop),
    so a run stops before it makes its folder."""
    from hybrid.terrain.datasets import NAMES
    from hybrid.terrain.paths import path_problem

    for entry in datasets:
        path = entry if isinstance(entry, str) else entry["path"]
        periodic = split_periodic(path)
        if periodic:
            path = periodic[0]
            if path in BUNDLED_STORES:
                continue
        elif path in NAMES:
            continue
        problem = path_problem(path)
        if problem == "no such file" and not Path(path).suffix and not periodic:
            raise TerrabenchError(
                f"{source}: unknown dataset {path!r}; choose one of {', '.join(NAMES)}, a file "
                "path or a tile store (terrabench prepare)"
            )
        if problem is not None:
            raise TerrabenchError(f"{source}: dataset {dataset_label(entry)!r}: {path}: {problem}")
