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
    return {"gl_renderer": info.renderer, "gl_vendor": info.vendor, "gl_version": info.version,
            "cpu": cpu, "cpu_count": os.cpu_count(), "python": platform.python_version(),
            "platform": platform.platform(), "packages": package_versions()}


def package_versions() -> dict[str, str]:
    """Versions of the packages that shape a run's numbers (or 'not installed')."""
    from importlib import metadata
    pkgs = {}
    for name in ("terrabench", "moderngl", "numpy", "pandas", "matplotlib", "scikit-image", "flip-evaluator",
                 "fast-simplification", "trimesh", "distributed"):
        try:
            pkgs[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pkgs[name] = "not installed"
    return pkgs
