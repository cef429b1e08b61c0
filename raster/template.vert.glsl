#version 430
#include "raster/tile_block"
#include "raster/tile_clip"
// The path without a geometry shader: the leaves' vertices written by the selection (raster/select.comp.glsl),
// tile-local metres and local level, drawn as one indexed draw per tile.
layout(location = 0) in vec4 a_vertex;    // (x, y) metres from tile sample [0, 0], z metres above the origin z, level
uniform mat4 view_proj_rel;               // (world - eye) -> clip, reversed Z
out vec3 v_rel;                           // eye-relative position; the fragment shader derives height and uv
flat out int v_level;
noperspective out vec3 v_bary;

void main() {
    vec3 p = origin_rel + a_vertex.xyz;
    v_rel = p;
    v_level = tile_level + int(a_vertex.w);
    v_bary = vec3(1.0);
    clip_to_tile(p, -1);
    gl_Position = view_proj_rel * vec4(p, 1.0);
}
