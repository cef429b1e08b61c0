"""GPU bytes of the moderngl buffers and textures an object holds, from the objects themselves.

The expected byte counts of the memory tests come from here, not from the size formulas under test: a
buffer's size is moderngl's ``Buffer.size``; a texture's is its texel size (components x the byte size of
its moderngl dtype) times the texels of every mip level the driver reports (glGetTextureLevelParameteriv).
"""

import ctypes
import dataclasses

import moderngl

from hybrid.gl.context import _gl_function

DTYPE_BYTES = {"f1": 1, "u1": 1, "i1": 1, "f2": 2, "u2": 2, "i2": 2, "f4": 4, "u4": 4, "i4": 4}
GL_TEXTURE_WIDTH, GL_TEXTURE_HEIGHT = 0x1000, 0x1001


def level_texels(tex) -> list[int]:
    """Texels of each allocated mip level of a texture, as the driver reports them (level 0 first)."""
    i = ctypes.c_int
    get = _gl_function(b"glGetTextureLevelParameteriv", ctypes.c_uint, i, ctypes.c_uint, ctypes.POINTER(i))
    out = []
    for level in range(32):
        w, h = i(), i()
        get(tex.glo, level, GL_TEXTURE_WIDTH, ctypes.byref(w))
        get(tex.glo, level, GL_TEXTURE_HEIGHT, ctypes.byref(h))
        if w.value == 0:
            break
        out.append(w.value * h.value)
    return out


def object_bytes(o) -> int:
    """Bytes of one moderngl Buffer or Texture."""
    if isinstance(o, moderngl.Buffer):
        return int(o.size)
    return o.components * DTYPE_BYTES[o.dtype] * sum(level_texels(o))


def gl_objects(obj):
    """The moderngl buffers and textures among an object's attributes (and those of the project's own objects
    it holds, directly or as a dict's values, such as a dataclass of textures or a holder of a uniform
    buffer)."""
    held = (w for v in vars(obj).values() for w in (v.values() if isinstance(v, dict) else (v,)))
    for v in held:  # a dict: e.g. a strategy's heaps by cell count
        if isinstance(v, (moderngl.Buffer, moderngl.Texture)):
            yield v
        elif isinstance(v, moderngl.Framebuffer):  # a held render target: its attachments
            yield from (t for t in (*v.color_attachments, v.depth_attachment) if isinstance(t, moderngl.Texture))
        elif (
            (
                (dataclasses.is_dataclass(v) and not isinstance(v, type))
                or (
                    type(v).__module__.split(".")[0] in ("raster", "raycast", "hybrid")
                    and hasattr(v, "__dict__")
                    and not callable(v)
                    and not isinstance(v, type)
                )
            )
            and v is not obj
            and not hasattr(v, "hf")
        ):  # strategies hold the terrain, not its GPU copies
            yield from gl_objects(v)


def allocated_bytes(obj) -> int:
    """Total bytes of the buffers and textures an object holds."""
    return sum(object_bytes(o) for o in gl_objects(obj))
