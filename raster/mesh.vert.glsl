#version 430
#include "raster/tile_block"
// Baseline meshes (full-resolution triangle list, decimated TIN): tile-local vertex positions in metres.
in vec3 a_pos;                 // (x, y) metres from tile sample [0, 0], z metres above the terrain origin z
uniform mat4 view_proj_rel;
out vec3 v_rel;                // eye-relative position; the fragment shader derives height and uv from it
flat out int v_level;
noperspective out vec3 v_bary;
out float gl_ClipDistance[4];
void main() {
    vec3 p = origin_rel + a_pos;
    v_rel = p;
    v_level = tile_level;
    v_bary = vec3(1.0);
    gl_ClipDistance[0] = p.x - clip_rel.x;
    gl_ClipDistance[1] = p.y - clip_rel.y;
    gl_ClipDistance[2] = clip_rel.z - p.x;
    gl_ClipDistance[3] = clip_rel.w - p.y;
    gl_Position = view_proj_rel * vec4(p, 1.0);
}
