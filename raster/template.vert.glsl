#version 430
#include "raster/tile_block"
#include "raster/tile_clip"
// The path without a geometry shader: the leaves' vertices written by the selection (raster/select.comp.glsl),
// tile-local metres and local level; every tile of a frame drawn in one multi-draw (MULTI_DRAW, raster.indexed).
layout(location = 0) in vec4 a_vertex;    // (x, y) metres from tile sample [0, 0], z metres above the origin z, level
#ifdef MULTI_DRAW
// Every item in one multi-draw: each draw's base instance is its item, whose block's first fields the frame's
// blocks buffer gives as instanced attributes (base instances offset instanced fetches: core GL 4.2).
layout(location = 1) in vec4 a_origin;
layout(location = 2) in vec4 a_spacing;
layout(location = 3) in vec4 a_clip_rel;
layout(location = 4) in vec4 a_uv;
layout(location = 5) in ivec4 a_shape;
out vec2 v_uv;                            // texture coordinate and height above the origin: the fragment shader
out float v_h;                            // cannot see the item (SURFACE_FROM_VERTEX)
#endif
uniform mat4 view_proj_rel;               // (world - eye) -> clip, reversed Z
out vec3 v_rel;                           // eye-relative position
flat out int v_level;
noperspective out vec3 v_bary;

void main() {
#ifdef MULTI_DRAW
    TB.t_origin = a_origin;
    TB.t_spacing = a_spacing;
    TB.t_clip_rel = a_clip_rel;
    TB.t_uv = a_uv;
    TB.t_shape = a_shape;
#endif
    vec3 p = origin_rel + a_vertex.xyz;
    v_rel = p;
#ifdef MULTI_DRAW
    v_uv = uv_origin + (p.xy - origin_rel.xy) / spacing * uv_per_cell;
    v_h = p.z - origin_rel.z;
#endif
    v_level = tile_level + int(a_vertex.w);
    v_bary = vec3(1.0);
    clip_to_tile(p, -1);
    gl_Position = view_proj_rel * vec4(p, 1.0);
}
