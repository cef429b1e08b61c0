"""The headless context: renderer reported, reversed-Z clip control set, bad device choices named."""

import ctypes

import numpy as np
import pytest
from gl_errors import gl_errors

from hybrid.errors import GLContextError
from hybrid.gl.context import _gl_function, create_context, depth32f_texture, driver_texture_bytes, gl_bytes, gl_info


def test_info_and_float_depth(ctx):
    info = gl_info(ctx)
    assert info.renderer != "?" and "4." in info.version
    tex = depth32f_texture(ctx, (8, 4))
    assert driver_texture_bytes(tex) == 8 * 4 * 4  # 32-bit float depth, not 24-bit fixed point
    fbo = ctx.framebuffer(color_attachments=[ctx.texture((8, 4), 4)], depth_attachment=tex)
    fbo.clear(depth=0.123456789)
    d = np.frombuffer(tex.read(), np.float32)
    assert np.all(d == np.float32(0.123456789))  # exact float storage
    fbo.release()
    tex.release()


def test_gl_bytes_counts_each_object_as_the_driver_sized_it(ctx):
    tex = ctx.texture((16, 8), 4)
    tex.build_mipmaps()
    buf = ctx.buffer(reserve=1000)
    levels = sum(max(16 >> k, 1) * max(8 >> k, 1) * 4 for k in range(5))  # 16x8 down to 1x1, RGBA8
    assert gl_bytes(tex, None, buf) == levels + 1000
    assert gl_bytes(tex, buf) == levels + 1000  # asked again: the same, from each object's slot
    assert tex.extra == {"driver_bytes": levels}
    tex.release()
    buf.release()


def test_missing_device_index_is_named(ctx):
    # needs a working EGL: only then does the error name the missing device rather than EGL itself
    with pytest.raises(GLContextError, match="no EGL device with index 99"):
        create_context(99)


@pytest.mark.parametrize("device", [-1, "0", True])
def test_bad_device_index(device):
    with pytest.raises(GLContextError, match="integer >= 0"):
        create_context(device)


def test_bad_device_environment(monkeypatch):
    monkeypatch.setenv("TERRABENCH_GL_DEVICE", "gpu0")
    with pytest.raises(GLContextError, match="TERRABENCH_GL_DEVICE"):
        create_context()


def test_gl_errors_are_seen_and_cleared(ctx):
    # binding a framebuffer name that was never generated is GL_INVALID_OPERATION in a core context
    bind = _gl_function(b"glBindFramebuffer", ctypes.c_uint, ctypes.c_uint)
    bind(0x8D40, 987654)  # GL_FRAMEBUFFER
    assert gl_errors(ctx) == ["GL_INVALID_OPERATION"]
    assert gl_errors(ctx) == []


def test_timed_with_a_timer_query_returns_the_gpu_time(ctx, monkeypatch):
    # the branch GPUs take (llvmpipe's queries are untrusted, so it is forced here): the query is read and freed
    from hybrid.gl.timing import timed, timer_queries_valid

    timer_queries_valid(ctx)
    monkeypatch.setitem(ctx.extra, "timer_queries", True)
    fbo = ctx.simple_framebuffer((64, 64))
    out, wall, gpu, issue = timed(ctx, lambda: fbo.clear(0.2, 0.4, 0.6, 1.0) or "drawn")
    assert out == "drawn" and wall >= 0.0 and 0.0 <= issue <= wall
    assert isinstance(gpu, float) and np.isfinite(gpu) and gpu >= 0.0
    assert np.frombuffer(fbo.read(components=4), np.uint8)[:4].tolist() == [51, 102, 153, 255]
    fbo.release()
