"""Headless OpenGL context through EGL (Mesa llvmpipe or an NVIDIA GPU), with the project's GL conventions.

Depth convention, used by every renderer: reversed Z. ``glClipControl(GL_LOWER_LEFT, GL_ZERO_TO_ONE)`` is
set once when the context is made, projections map the near plane to depth 1 and the far plane to 0, the
depth buffer is 32-bit float, cleared to 0, and the depth test is GREATER. This keeps the relative depth
precision near 1e-7 at every distance, so raster and ray-cast tiles resolve the same way at 100 km.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from hybrid.errors import GLContextError, TerrabenchError
from hybrid.gl.programs import register_shared_includes

GL_LOWER_LEFT = 0x8CA1
GL_ZERO_TO_ONE = 0x935F
DEVICE_ENV = "TERRABENCH_GL_DEVICE"


@dataclass(frozen=True)
class GLInfo:
    """What the driver reports about the context."""

    renderer: str
    vendor: str
    version: str
    glsl: str
    device_index: int | None

    @property
    def is_software(self) -> bool:
        """True on Mesa's CPU rasterizers (llvmpipe, softpipe), where GPU timer queries are wrong."""
        r = self.renderer.lower()
        return "llvmpipe" in r or "softpipe" in r or "swrast" in r


_EGL = None
_FUNCTIONS: dict = {}


def _proc_address(name: bytes) -> int:
    global _EGL
    if _EGL is None:
        _EGL = ctypes.CDLL(ctypes.util.find_library("EGL") or "libEGL.so.1")
        _EGL.eglGetProcAddress.restype = ctypes.c_void_p
        _EGL.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    return _EGL.eglGetProcAddress(name) or 0


def _set_clip_control() -> None:
    addr = _proc_address(b"glClipControl")
    if not addr:
        raise GLContextError("the GL driver has no glClipControl (needs OpenGL 4.5 or ARB_clip_control)")
    fn = ctypes.CFUNCTYPE(None, ctypes.c_uint, ctypes.c_uint)(addr)
    fn(GL_LOWER_LEFT, GL_ZERO_TO_ONE)


def create_context(device: int | None = None, require: int = 430):
    """Make a headless EGL core context (GL >= 4.3), set reversed-Z clip control, and return it.

    ``device`` picks an EGL device by index; when None, the environment variable TERRABENCH_GL_DEVICE is
    used if set. Any failure ends in GLContextError with the reason.
    """
    try:
        import moderngl
    except ImportError as exc:  # pragma: no cover - dependency is declared
        raise GLContextError(f"moderngl is not installed: {exc}") from None
    if device is None and os.environ.get(DEVICE_ENV, "") != "":
        raw = os.environ[DEVICE_ENV]
        try:
            device = int(raw)
        except ValueError:
            raise GLContextError(f"{DEVICE_ENV} must be a device index >= 0, got {raw!r}") from None
    kwargs: dict[str, Any] = {"backend": "egl", "require": require}
    if device is not None:
        if isinstance(device, bool) or not isinstance(device, int) or device < 0:
            raise GLContextError(f"GL device index must be an integer >= 0, got {device!r}")
        kwargs["device_index"] = device
    try:
        ctx = moderngl.create_standalone_context(**kwargs)
    except Exception as exc:  # glcontext raises bare Exceptions with terse texts
        text = str(exc).strip() or type(exc).__name__
        if device is not None and ("device" in text.lower() or "index" in text.lower()):
            raise GLContextError(f"no EGL device with index {device} ({text})") from None
        if "libEGL" in text or "egl" in text.lower():
            raise GLContextError(
                f"cannot open a headless EGL context ({text}); install Mesa's EGL (libegl1, libgl1-mesa-dri)"
            ) from None
        raise GLContextError(
            f"cannot create an OpenGL {require // 100}.{require % 100 // 10} core context: {text}"
        ) from None
    if ctx.version_code < require:
        ver = ctx.info.get("GL_VERSION", "?")
        ctx.release()
        raise GLContextError(
            f"OpenGL {require // 100}.{require % 100 // 10} or newer is needed, the driver gives {ver}"
        )
    _set_clip_control()
    register_shared_includes(ctx)
    ctx.extra = {"device_index": device}
    return ctx


def gl_info(ctx) -> GLInfo:
    """Renderer, vendor and version strings of a context."""
    info = ctx.info
    extra = getattr(ctx, "extra", None) or {}
    return GLInfo(
        renderer=str(info.get("GL_RENDERER", "?")),
        vendor=str(info.get("GL_VENDOR", "?")),
        version=str(info.get("GL_VERSION", "?")),
        glsl=str(info.get("GL_SHADING_LANGUAGE_VERSION", "?")),
        device_index=extra.get("device_index"),
    )


_SHARED: dict = {}


def shared_context(device: int | None = None):
    """One process-wide context per device (made on first use), for the CLI and the tests.

    Standalone contexts do not switch on use, so a process should draw with one context only.
    """
    if device not in _SHARED:
        _SHARED[device] = create_context(device)
    return _SHARED[device]


_WAITED = [0.0]  # ms spent waiting for the GL by this process (the GL runs on one thread)


def gl_finish(ctx) -> None:
    """glFinish on the current context, through ctypes, which lets other Python threads run while the GL works
    (moderngl's ctx.finish() and buffer reads hold the interpreter lock while they wait); the wait is added to
    ``gl_waited_ms``."""
    t0 = time.perf_counter()
    _gl_function(b"glFinish")()
    _WAITED[0] += (time.perf_counter() - t0) * 1e3


def gl_memory_barrier(ctx) -> None:
    """glMemoryBarrier (all bits). A CPU rasterizer finishes the queued work there, so on one the call's time is
    added to ``gl_waited_ms``; on a GPU the call does not wait. Called through ctypes, which lets other Python
    threads (a tile store's loader) run while the rasterizer works (moderngl's holds the interpreter lock)."""
    t0 = time.perf_counter()
    _gl_function(b"glMemoryBarrier", ctypes.c_uint)(0xFFFFFFFF)  # GL_ALL_BARRIER_BITS
    if is_software(ctx):
        _WAITED[0] += (time.perf_counter() - t0) * 1e3


def context_extra(ctx) -> dict:
    """The dict a context carries for the project's per-context facts (``ctx.extra``), made if missing."""
    extra = getattr(ctx, "extra", None)
    if not isinstance(extra, dict):
        extra = ctx.extra = {}
    return extra


def max_texture_size(ctx) -> int:
    """The widest 2-D texture this context takes (texels a side): GL_MAX_TEXTURE_SIZE, or less where a test set
    ``context_extra(ctx)["max_texture_size"]`` to exercise layouts that wrap at the limit."""
    limit = int(ctx.info["GL_MAX_TEXTURE_SIZE"])
    forced = context_extra(ctx).get("max_texture_size")
    return min(limit, int(forced)) if forced else limit


def is_software(ctx) -> bool:
    """True on a CPU rasterizer (llvmpipe, softpipe); cached on the context."""
    extra = context_extra(ctx)
    if "software" not in extra:
        extra["software"] = gl_info(ctx).is_software
    return extra["software"]


def gl_waited_ms() -> float:
    """Milliseconds this process has spent waiting for the GL to finish its work (``gl_finish``, and
    ``gl_memory_barrier`` on a CPU rasterizer)."""
    return _WAITED[0]


def _gl_function(name: bytes, *argtypes):
    key = (name, argtypes)
    if key not in _FUNCTIONS:
        addr = _proc_address(name)
        if not addr:
            raise GLContextError(f"the GL driver has no {name.decode()}")
        _FUNCTIONS[key] = ctypes.CFUNCTYPE(None, *argtypes)(addr)
    return _FUNCTIONS[key]


GL_DRAW_INDIRECT_BUFFER, GL_UNSIGNED_INT = 0x8F3F, 0x1405


def multi_draw_indirect(vao, commands, mode: int, first_byte: int, count: int, stride: int) -> None:
    """glMultiDrawElementsIndirect: ``count`` indexed draws (32-bit indices) of vertex array ``vao`` with its
    program, their commands ``stride`` bytes apart from byte ``first_byte`` of buffer ``commands`` (moderngl's
    render_indirect reads commands 20 bytes apart only). moderngl binds the program, vertex array and indirect
    buffer again at each of its own draws, so these raw bindings do not leak into them."""
    u = ctypes.c_uint
    _gl_function(b"glUseProgram", u)(vao.program.glo)
    _gl_function(b"glBindVertexArray", u)(vao.glo)
    _gl_function(b"glBindBuffer", u, u)(GL_DRAW_INDIRECT_BUFFER, commands.glo)
    _gl_function(b"glMultiDrawElementsIndirect", u, u, ctypes.c_void_p, ctypes.c_int, ctypes.c_int)(
        mode, GL_UNSIGNED_INT, first_byte, count, stride
    )


def depth32f_texture(ctx, size: tuple[int, int]):
    """A depth texture with 32-bit float storage (GL_DEPTH_COMPONENT32F), usable as depth attachment.

    moderngl's depth_texture allocates 24-bit fixed point, which wastes reversed Z; the storage is
    re-specified through the driver directly.
    """
    tex = ctx.depth_texture(tuple(size))
    u, i = ctypes.c_uint, ctypes.c_int
    bind = _gl_function(b"glBindTexture", u, u)
    image = _gl_function(b"glTexImage2D", u, i, i, i, i, i, u, u, ctypes.c_void_p)
    GL_TEXTURE_2D, GL_DEPTH_COMPONENT32F, GL_DEPTH_COMPONENT, GL_FLOAT = 0x0DE1, 0x8CAC, 0x1902, 0x1406
    bind(GL_TEXTURE_2D, tex.glo)
    image(GL_TEXTURE_2D, 0, GL_DEPTH_COMPONENT32F, int(size[0]), int(size[1]), 0, GL_DEPTH_COMPONENT, GL_FLOAT, None)
    bind(GL_TEXTURE_2D, 0)
    tex.filter = (ctx.NEAREST, ctx.NEAREST) if hasattr(ctx, "NEAREST") else tex.filter
    return tex


_BYTES_PER_TEXEL = {
    0x822E: 4,
    0x8058: 4,
    0x8051: 3,
    0x8236: 4,
    0x8CAC: 4,
    0x81A6: 4,
    0x8229: 1,
    0x822D: 2,
    0x8814: 16,
    0x8815: 12,
    0x8230: 8,
    0x8234: 2,
}
# R32F RGBA8 RGB8 R32UI DEPTH32F DEPTH24 R8 R16F RGBA32F RGB32F RG32F R16UI


# single-channel texel formats of max-mip textures: numpy dtype -> (moderngl dtype, internal format, format, type)
RED_FORMATS = {
    np.dtype(np.uint16): ("u2", 0x8234, 0x8D94, 0x1403),  # R16UI, RED_INTEGER, UNSIGNED_SHORT
    np.dtype(np.float32): ("f4", 0x822E, 0x1903, 0x1406),  # R32F, RED, FLOAT
}


def _red_format(dtype) -> tuple[str, int, int, int]:
    """(moderngl dtype, internal format, format, type) of a single-channel texel dtype, else refused."""
    fmt = RED_FORMATS.get(np.dtype(dtype))
    if fmt is None:
        raise TerrabenchError(f"mip textures hold uint16 or float32 texels, got {np.dtype(dtype)}")
    return fmt


def red_mip_texture(ctx, size: int, levels: int, dtype=np.uint16):
    """A size x size single-channel texture (R16UI for uint16, R32F for float32) with ``levels`` mip levels
    allocated, NEAREST filtered, contents undefined (a compute pass fills them).

    moderngl allocates only level 0 and cannot build mipmaps of integer textures (glGenerateMipmap refuses
    them, and would average floats), so the coarser levels are specified through the driver directly.
    """
    mgl, internal, fmt, typ = _red_format(dtype)
    tex = ctx.texture((int(size), int(size)), 1, None, dtype=mgl, alignment=1)
    u, i = ctypes.c_uint, ctypes.c_int
    bind = _gl_function(b"glBindTexture", u, u)
    image = _gl_function(b"glTexImage2D", u, i, i, i, i, i, u, u, ctypes.c_void_p)
    param = _gl_function(b"glTexParameteri", u, u, i)
    GL_TEXTURE_2D, GL_TEXTURE_MAX_LEVEL = 0x0DE1, 0x813D
    bind(GL_TEXTURE_2D, tex.glo)
    for level in range(1, int(levels)):
        m = max(int(size) >> level, 1)
        image(GL_TEXTURE_2D, level, internal, m, m, 0, fmt, typ, None)
    param(GL_TEXTURE_2D, GL_TEXTURE_MAX_LEVEL, int(levels) - 1)
    bind(GL_TEXTURE_2D, 0)
    tex.filter = (ctx.NEAREST_MIPMAP_NEAREST if levels > 1 else ctx.NEAREST, ctx.NEAREST)
    tex.repeat_x = tex.repeat_y = False
    return tex


def read_r16ui_level(tex, level: int) -> np.ndarray:
    """One mip level of an R16UI texture as a uint16 (height, width) array (moderngl reads only the levels it
    allocated itself)."""
    u, i = ctypes.c_uint, ctypes.c_int
    get = _gl_function(b"glGetTextureLevelParameteriv", u, i, u, ctypes.POINTER(i))
    w, h = i(), i()
    get(tex.glo, int(level), 0x1000, ctypes.byref(w))
    get(tex.glo, int(level), 0x1001, ctypes.byref(h))
    out = np.zeros((h.value, w.value), np.uint16)
    _gl_function(b"glPixelStorei", u, i)(0x0D05, 1)  # GL_PACK_ALIGNMENT
    image = _gl_function(b"glGetTextureImage", u, i, u, u, i, ctypes.c_void_p)
    image(tex.glo, int(level), 0x8D94, 0x1403, out.nbytes, out.ctypes.data)  # GL_RED_INTEGER, GL_UNSIGNED_SHORT
    return out


def driver_texture_bytes(tex) -> int:
    """Bytes of all mip levels of a texture as the driver reports them (width x height x texel size)."""
    u, i = ctypes.c_uint, ctypes.c_int
    get = _gl_function(b"glGetTextureLevelParameteriv", u, i, u, ctypes.POINTER(i))
    total, level = 0, 0
    while level < 32:
        w, h, f = i(), i(), i()
        get(tex.glo, level, 0x1000, ctypes.byref(w))  # GL_TEXTURE_WIDTH
        if w.value == 0:
            break
        get(tex.glo, level, 0x1001, ctypes.byref(h))  # GL_TEXTURE_HEIGHT
        get(tex.glo, level, 0x1003, ctypes.byref(f))  # GL_TEXTURE_INTERNAL_FORMAT
        if f.value not in _BYTES_PER_TEXEL:
            raise GLContextError(f"unknown texture internal format 0x{f.value:x}")
        total += w.value * h.value * _BYTES_PER_TEXEL[f.value]
        level += 1
    return total


def gl_bytes(*objects) -> int:
    """Bytes of moderngl textures and buffers as the driver reports them (None entries count 0).

    The project never resizes a texture or buffer after making it (a bigger one is a new object, and mip levels
    are allocated or built before the object is handed out), so the driver is asked once per object and its
    answer kept in the object's ``extra`` slot: the renderer accounts its memory every frame."""
    total = 0
    for o in objects:
        if o is None:
            continue
        extra = o.extra if isinstance(o.extra, dict) else None
        n = extra.get("driver_bytes") if extra is not None else None
        if n is None:
            n = driver_buffer_bytes(o) if hasattr(o, "bind_to_storage_buffer") else driver_texture_bytes(o)
            if extra is not None:
                extra["driver_bytes"] = n
            elif o.extra is None:
                o.extra = {"driver_bytes": n}
        total += n
    return total


def driver_buffer_bytes(buf) -> int:
    """Size of a buffer object as the driver reports it (GL_BUFFER_SIZE)."""
    u, i = ctypes.c_uint, ctypes.c_int
    get = _gl_function(b"glGetNamedBufferParameteriv", u, u, ctypes.POINTER(i))
    n = i()
    get(buf.glo, 0x8764, ctypes.byref(n))
    return n.value
