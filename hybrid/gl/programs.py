"""GLSL sources that live as .glsl files beside the Python that loads them, and their one include mechanism.

Includes go through moderngl's ``ctx.includes``: a shader says ``#include "shading"`` and the context
supplies the text. The shared includes (``SHARED_INCLUDES``) are registered once, where the context is made
(``hybrid.gl.context.create_context``); a strategy registers its own package-local includes on the context
with ``register_include`` before it compiles. ``#define`` lines are placed right after ``#version``.
"""

from __future__ import annotations

from importlib import resources

# include name -> (package, file): the colour conventions every method shades with
SHARED_INCLUDES = {"shading": ("hybrid.gl", "shading.glsl"), "terrain_edges": ("hybrid.gl", "edges.glsl")}


def glsl_source(package: str, name: str, defines: dict | None = None) -> str:
    """Text of the GLSL file NAME of PACKAGE, with ``#define K V`` lines inserted after ``#version``."""
    text = (resources.files(package) / name).read_text()
    if not defines:
        return text
    out = []
    for line in text.splitlines():
        out.append(line)
        if line.strip().startswith("#version"):
            out.extend(f"#define {k} {v}" for k, v in defines.items())
    return "\n".join(out) + "\n"


def register_include(ctx, include: str, package: str, name: str) -> None:
    """Make ``#include "INCLUDE"`` resolve to the GLSL file NAME of PACKAGE in every program of ctx."""
    ctx.includes[include] = glsl_source(package, name)


def register_shared_includes(ctx) -> None:
    """Register every shared include (SHARED_INCLUDES) on a new context."""
    for include, (package, name) in SHARED_INCLUDES.items():
        register_include(ctx, include, package, name)


def program(
    ctx,
    package: str,
    vertex: str,
    fragment: str | None = None,
    geometry: str | None = None,
    defines: dict | None = None,
):
    """A linked program from the GLSL files of PACKAGE (includes resolved by ctx.includes)."""

    def src(name):
        return None if name is None else glsl_source(package, name, defines)

    return ctx.program(vertex_shader=src(vertex), fragment_shader=src(fragment), geometry_shader=src(geometry))


def compute_shader(ctx, package: str, name: str, defines: dict | None = None):
    """A compute shader from the GLSL file NAME of PACKAGE."""
    return ctx.compute_shader(glsl_source(package, name, defines))


def set_uniform(prog, name: str, value) -> None:
    """Set a uniform if the linked program kept it (compilers drop unused uniforms). Looked up with
    ``Program.get`` (a dict): ``name in prog`` walks every member of the program in Python."""
    u = prog.get(name, None)
    if u is not None:
        u.value = value


def write_uniform(prog, name: str, data: bytes) -> None:
    """Write a uniform's raw bytes (matrices) if the linked program kept it."""
    u = prog.get(name, None)
    if u is not None:
        u.write(data)


_UNSET = object()


class UniformCache:
    """The uniform values last sent to programs through it. A program keeps its uniforms between draws, so a value
    it already holds is not sent again: the per-frame uniforms that rarely change cost no GL call. Every write to
    those uniforms must go through the cache (one per owner of the programs)."""

    def __init__(self):
        self._held: dict = {}

    def set(self, prog, name: str, value) -> None:
        """``set_uniform(prog, name, value)`` unless prog already holds that value."""
        key = (id(prog), name)
        if self._held.get(key, _UNSET) != value:
            set_uniform(prog, name, value)
            self._held[key] = value
