"""GLSL sources of the ray caster, read from the package with one-level ``//#include NAME`` expansion."""
from __future__ import annotations

from importlib import resources


def load_glsl(name: str, defines: dict | None = None) -> str:
    """Text of raycast/NAME with ``//#include FILE`` lines expanded and ``#define K V`` lines after #version."""
    text = (resources.files("raycast") / name).read_text()
    out = []
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("//#include "):
            out.append((resources.files("raycast") / s.split(None, 1)[1]).read_text())
        else:
            out.append(line)
        if s.startswith("#version") and defines:
            out.extend(f"#define {k} {v}" for k, v in defines.items())
    return "\n".join(out) + "\n"
