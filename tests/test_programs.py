"""Every GLSL program compiles and links, through the one include mechanism, and every .glsl file is used."""
from pathlib import Path

import pytest

import hybrid.gl.programs as programs
from hybrid.errors import TerrabenchError
from hybrid.reference import ReferenceRenderer
from raster.indexed import IndexedTileletStrategy
from raster.tilelets import TileletStrategy
from raster.trianglelist import TriangleListStrategy
from raycast import CastOptions, RaycastStrategy
from raycast.options import MODES as CAST_MODES
from raycast.options import RECONSTRUCTIONS

ROOT = Path(__file__).resolve().parent.parent


def test_every_program_compiles_and_every_glsl_file_is_used(ctx, puget257, monkeypatch):
    loaded = set()
    real = programs.glsl_source

    def recording(package, name, defines=None):
        loaded.add(str(Path(*package.split(".")) / name))
        return real(package, name, defines)

    monkeypatch.setattr(programs, "glsl_source", recording)
    ctx.error                                              # clear any stale error
    made = [ReferenceRenderer(ctx, puget257), TileletStrategy(ctx, puget257), IndexedTileletStrategy(ctx, puget257),
            TriangleListStrategy(ctx, puget257)]
    rc = RaycastStrategy(ctx, puget257)
    made.append(rc)
    variants = [CastOptions(reconstruction=r, mode=m) for r in RECONSTRUCTIONS for m in CAST_MODES]
    variants += [CastOptions(traversal="naive"), CastOptions(lod=0.5), CastOptions(prepass=False),
                 CastOptions(stats=False), CastOptions(shadows=True)]
    for opts in variants:
        prog, _ = rc._program(opts, rc._check_mode(opts))
        assert prog.glo > 0
    assert ctx.error == "GL_NO_ERROR"
    for o in made:
        o.release()
    shared = {str(Path(*pkg.split(".")) / name) for pkg, name in programs.SHARED_INCLUDES.values()}
    on_disk = {str(p.relative_to(ROOT)) for pkg in ("hybrid", "raster", "raycast") for p in (ROOT / pkg).rglob("*.glsl")}
    assert on_disk - loaded - shared == set(), "GLSL files no program uses"


def test_include_is_resolved_by_the_context(ctx):
    assert "shading" in ctx.includes                       # registered where the context was made
    src = "#version 430\n#include \"shading\"\nout vec4 c;\nvoid main() { c = vec4(1.0); }\n"
    prog = ctx.program(vertex_shader="#version 430\nvoid main() { gl_Position = vec4(0.0); }\n", fragment_shader=src)
    prog.release()
    with pytest.raises(KeyError, match="cannot include"):
        ctx.program(vertex_shader="#version 430\n#include \"nowhere\"\nvoid main() { gl_Position = vec4(0.0); }\n")


def test_defines_follow_the_version_line():
    text = programs.glsl_source("raycast", "raycast.frag.glsl", {"RECON": 2, "MODE": 0})
    lines = text.splitlines()
    assert lines[0].startswith("#version") and lines[1:3] == ["#define RECON 2", "#define MODE 0"]


def test_unknown_mode_is_refused(ctx, puget257):
    from hybrid.camera.view import default_view
    with ReferenceRenderer(ctx, puget257) as ref, pytest.raises(TerrabenchError, match="unknown shading mode 'glow'"):
        ref.render(default_view(puget257, 32, 18), mode="glow")
