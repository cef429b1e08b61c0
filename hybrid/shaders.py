"""Loading GLSL sources that live beside the Python modules, with one-level ``//#include NAME`` lines."""
from __future__ import annotations

from importlib import resources


def load_source(package: str, name: str) -> str:
    """Text of a .glsl/.vert/.frag/.geom file in a package, with ``//#include FILE`` lines expanded."""
    text = (resources.files(package) / name).read_text()
    out = []
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("//#include "):
            out.append((resources.files(package) / s.split(None, 1)[1]).read_text())
        else:
            out.append(line)
    return "\n".join(out) + "\n"
