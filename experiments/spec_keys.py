"""The checks of an experiment spec's keys: lists (type, allowed names, each entry once) and scalars (type, range).

The names a key allows come from the strategy registry where they name policies or strategy options
(``hybrid.strategies``); the dataset entries have their own checks (``experiments.spec_datasets``).
"""

from __future__ import annotations

from typing import Any

from hybrid.camera.view import parse_size
from hybrid.errors import TerrabenchError
from hybrid.strategies import methods, option_choices

START_MODELS = ("device", "fallback")
"""The hybrid's starting cost models: this GL renderer's as loaded (``hybrid.cost.model.load_cost_model``: the
user's file, the shipped default, else the fallback), or the shipped uncalibrated fallback."""


def checked_list(d, key, kind, check=None):
    """The list ``d[key]`` (None when absent), checked: non-empty, entries of ``kind`` passing ``check``, each once."""
    v = d.get(key)
    if v is None:
        return None
    if not isinstance(v, list) or not v:
        raise TerrabenchError(f"spec: '{key}' must be a non-empty list, got {v!r}")
    for x in v:
        if not isinstance(x, kind) or isinstance(x, bool):
            raise TerrabenchError(f"spec: '{key}' entries must be {getattr(kind, '__name__', kind)}, got {x!r}")
        if check:
            check(x)
    seen = [repr(x) for x in v]
    twice = sorted({x for x in seen if seen.count(x) > 1})
    if twice:
        raise TerrabenchError(f"spec: '{key}' lists {', '.join(twice)} more than once; each entry once")
    return v


def list_keys(source: str) -> tuple:
    """(key, entry check or None) of every list key of a flights spec but ``datasets`` (its entries' type is the
    ``Spec`` field's); the names a key allows come from the strategy registry where they name policies or options."""

    def one_of(what: str, allowed: tuple):
        def check(v):
            if v not in allowed:
                raise TerrabenchError(f"{source}: unknown {what} {v!r}; choose from {', '.join(allowed)}")

        return check

    def tau_ok(t):
        if not (t > 0 and t < 1e3):
            raise TerrabenchError(f"{source}: tau must lie in (0, 1000) pixels, got {t!r}")

    def size_ok(s):
        parse_size(s, f"{source}: size")

    def seed_ok(s):
        if not (0 <= s < 2**32):
            raise TerrabenchError(f"{source}: seeds must lie in [0, 2^32), got {s!r}")

    return (
        ("flights", None),
        ("policies", one_of("policy", methods())),
        ("taus", tau_ok),
        ("sizes", size_ok),
        ("reconstructions", one_of("reconstruction", option_choices("reconstruction"))),
        ("full_res", one_of("full_res", option_choices("full_res"))),
        ("seeds", seed_ok),
        ("start_models", one_of("start model", START_MODELS)),
        ("image_frames", None),
    )


def scalar_keys(d: dict, source: str, flags: list[str]) -> dict:
    """The spec's integer, number and true/false keys (``flags``: the ``Spec`` fields typed bool) that ``d`` gives,
    checked."""
    kw: dict[str, Any] = {}
    for key, lo, hi in (
        ("frames", 1, 100000),
        ("repeats", 3, 1000),
        ("tile_size", 2, 65536),
        ("supersample", 1, 8),
        ("dataset_size", 0, 16385),
        ("gpu_budget_mib", 1, 1 << 20),
        ("reuse_choice", 1, 1000),
    ):
        if key in d:
            v = d[key]
            if isinstance(v, bool) or not isinstance(v, int) or not (lo <= v <= hi):
                raise TerrabenchError(f"{source}: '{key}' must be an integer in [{lo}, {hi}], got {v!r}")
            kw[key] = v
    if "tile_size" in kw and kw["tile_size"] & (kw["tile_size"] - 1):
        raise TerrabenchError(f"{source}: 'tile_size' must be a power of two, got {kw['tile_size']}")
    if "upload_budget_ms" in d:
        v = d["upload_budget_ms"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0 <= v <= 1e4):
            raise TerrabenchError(f"{source}: 'upload_budget_ms' must be a number of ms in [0, 10000], got {v!r}")
        kw["upload_budget_ms"] = float(v)
    for key in flags:
        if key in d:
            if not isinstance(d[key], bool):
                raise TerrabenchError(f"{source}: '{key}' must be true or false, got {d[key]!r}")
            kw[key] = d[key]
    return kw
