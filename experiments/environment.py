"""What a run records about where it ran: GL renderer, CPU, Python and the versions of the packages that shape
its numbers."""

from __future__ import annotations

import platform
from pathlib import Path


def environment(ctx) -> dict:
    """GL renderer, CPU and package versions of this machine."""
    from hybrid.gl.context import gl_info

    info = gl_info(ctx)
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import os

    return {
        "gl_renderer": info.renderer,
        "gl_vendor": info.vendor,
        "gl_version": info.version,
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "packages": package_versions(),
        "cost_model": cost_model_fingerprint(info.renderer),
    }


def cost_model_fingerprint(renderer: str, sent: dict | None = None) -> dict:
    """Where the hybrid's cost model for a GL renderer comes from and a short hash of its coefficients, so that a
    resumed run can tell whether its earlier frames were chosen by the same model: the model of ``sent`` (a costs
    file's models by renderer, as a cluster's client sends them) where it has one, else this machine's own."""
    import hashlib
    import json

    from hybrid.cost.model import costs_file_model, load_cost_model

    model = costs_file_model(sent, renderer, "costs file sent by the client") if sent else None
    if model is None:
        model = load_cost_model(renderer)
    d = model.to_dict()
    d.pop("source", None)
    digest = hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:12]
    return {"source": model.source, "sha256": digest, "full_res": model.full_res}


def cost_model_line(env: dict) -> str:
    """The hybrid's cost model as an env.json records it (one, or one per GL renderer of a cluster), in words."""
    cm = env.get("cost_model") or {}
    models = {"": cm} if "source" in cm else cm

    def one(m: dict) -> str:
        rule = f", its raster frames drawn with full_res {m['full_res']!r}" if "full_res" in m else ""
        return f"{m.get('source', '?')} (sha256 {m.get('sha256', '?')}{rule})"

    return "; ".join(f"{r + ': ' if r else ''}{one(m)}" for r, m in models.items()) or "not recorded"


def adaptation_line(spec: dict) -> str:
    """Whether the run's hybrids refit their cost model as they drew (the spec's ``adapt``) and the models they
    started from (``start_models``), in words."""
    starts = {"device": "this device's model as loaded (above)", "fallback": "the uncalibrated fallback"}
    named = ", ".join(starts.get(s, s) for s in spec.get("start_models", ["device"]))
    if not spec.get("adapt", True):
        return f"no, frozen at the model it started from ({named})"
    return f"yes, refitted online from the frames it drew, starting from {named}"


RESUME_KEYS = ("gl_renderer", "cost_model")
"""What must match between a run folder's earlier frames and a resumed run's (frames of another device or cost
model would sit in one table as if measured together)."""


def resume_mismatch(old: dict, new: dict) -> str | None:
    """A sentence naming what differs in ``RESUME_KEYS`` between an earlier run's env.json and this one's, else
    None (a key the earlier run did not record is not compared)."""
    diffs = [f"{k} {old[k]!r} then, {new.get(k)!r} now" for k in RESUME_KEYS if k in old and old[k] != new.get(k)]
    return "; ".join(diffs) or None


def package_versions() -> dict[str, str]:
    """Versions of the packages that shape a run's numbers (or 'not installed')."""
    from importlib import metadata

    pkgs = {}
    for name in (
        "terrabench",
        "moderngl",
        "numpy",
        "pandas",
        "matplotlib",
        "scikit-image",
        "flip-evaluator",
        "fast-simplification",
        "trimesh",
        "distributed",
    ):
        try:
            pkgs[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pkgs[name] = "not installed"
    return pkgs
