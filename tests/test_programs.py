"""Every GLSL program compiles and links, through the one include mechanism, and every .glsl file is used."""

from pathlib import Path

import pytest

import hybrid.gl.programs as programs
from hybrid.errors import TerrabenchError
from hybrid.gl.brush import GpuHeights
from hybrid.gl.deform import GpuDeformations
from hybrid.gl.particles import ParticleParams, ParticleSystem
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
    _ = ctx.error  # clear any stale error
    made = [
        ReferenceRenderer(ctx, puget257),
        TileletStrategy(ctx, puget257),
        IndexedTileletStrategy(ctx, puget257),
        TriangleListStrategy(ctx, puget257),
    ]
    rc = RaycastStrategy(ctx, puget257)
    heights = GpuHeights(ctx, puget257)  # the editing passes: brushes and deformations
    made += [rc, GpuDeformations(heights), ParticleSystem(ctx, heights, ParticleParams(count=64)), heights]
    variants = [CastOptions(reconstruction=r, mode=m) for r in RECONSTRUCTIONS for m in CAST_MODES]
    variants += [
        CastOptions(traversal="naive"),
        CastOptions(lod=0.5),
        CastOptions(prepass=False),
        CastOptions(stats=False),
        CastOptions(shadows=True),
    ]
    for opts in variants:
        prog, _ = rc._program(opts, rc._check_mode(opts))
        assert prog.glo > 0
    assert ctx.error == "GL_NO_ERROR"
    for o in made:
        o.release()
    shared = {str(Path(*pkg.split(".")) / name) for pkg, name in programs.SHARED_INCLUDES.values()}
    on_disk = {
        str(p.relative_to(ROOT)) for pkg in ("hybrid", "raster", "raycast") for p in (ROOT / pkg).rglob("*.glsl")
    }
    assert on_disk - loaded - shared == set(), "GLSL files no program uses"


def test_include_is_resolved_by_the_context(ctx):
    assert "shading" in ctx.includes  # registered where the context was made
    src = '#version 430\n#include "shading"\nout vec4 c;\nvoid main() { c = vec4(1.0); }\n'
    prog = ctx.program(vertex_shader="#version 430\nvoid main() { gl_Position = vec4(0.0); }\n", fragment_shader=src)
    prog.release()
    with pytest.raises(KeyError, match="cannot include"):
        ctx.program(vertex_shader='#version 430\n#include "nowhere"\nvoid main() { gl_Position = vec4(0.0); }\n')


def test_defines_follow_the_version_line():
    text = programs.glsl_source("raycast", "raycast.frag.glsl", {"RECON": 2, "MODE": 0})
    lines = text.splitlines()
    assert lines[0].startswith("#version") and lines[1:3] == ["#define RECON 2", "#define MODE 0"]


def test_unknown_mode_is_refused(ctx, puget257):
    from hybrid.camera.view import default_view

    with ReferenceRenderer(ctx, puget257) as ref, pytest.raises(TerrabenchError, match="unknown shading mode 'glow'"):
        ref.render(default_view(puget257, 32, 18), mode="glow")


def test_tile_block_offsets_are_the_drivers(ctx, puget257):
    """The ray caster's per-tile uniform block (tile_block.glsl) is written with std140 offsets computed in
    raycast.tile_params; the linked program's own offsets of every member, asked from the driver, are those."""
    import ctypes

    from hybrid.gl.context import _gl_function
    from raycast.tile_params import TILE_BLOCK

    rc = RaycastStrategy(ctx, puget257)
    opts = CastOptions(shadows=True, prepass=True, lod=0.5)
    prog, _ = rc._program(opts, rc._check_mode(opts))
    names = list(TILE_BLOCK.names)
    c_names = (ctypes.c_char_p * len(names))(*[n.encode() for n in names])
    idx = (ctypes.c_uint * len(names))()
    _gl_function(
        b"glGetUniformIndices",
        ctypes.c_uint,
        ctypes.c_int,
        ctypes.POINTER(ctypes.c_char_p),
        ctypes.POINTER(ctypes.c_uint),
    )(prog.glo, len(names), c_names, idx)
    assert all(i != 0xFFFFFFFF for i in idx), dict(zip(names, idx))  # every member kept by the linker
    offsets = (ctypes.c_int * len(names))()
    _gl_function(
        b"glGetActiveUniformsiv",
        ctypes.c_uint,
        ctypes.c_int,
        ctypes.POINTER(ctypes.c_uint),
        ctypes.c_uint,
        ctypes.POINTER(ctypes.c_int),
    )(prog.glo, len(names), idx, 0x8A3B, offsets)  # GL_UNIFORM_OFFSET
    assert dict(zip(names, offsets)) == {n: TILE_BLOCK.fields[n][1] for n in names}
    rc.release()
