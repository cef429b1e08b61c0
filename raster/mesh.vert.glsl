#version 430
#include "raster/tile_block"
#include "raster/tile_clip"
// Baseline meshes (full-resolution triangle list, decimated TIN): tile-local vertex positions in metres.
in vec3 a_pos;                 // (x, y) metres from tile sample [0, 0], z metres above the terrain origin z
uniform mat4 view_proj_rel;
out vec3 v_rel;                // eye-relative position; the fragment shader derives height and uv from it
flat out int v_level;
noperspective out vec3 v_bary;
void main() {
    vec3 p = origin_rel + a_pos;
    v_rel = p;
    v_level = tile_level;
    v_bary = vec3(1.0);
    clip_to_tile(p, -1);
    gl_Position = view_proj_rel * vec4(p, 1.0);
}
