#version 430
#include "raster/tile_block"
#include "raster/tile_clip"
// Skirts of the indexed path (raster.indexed): one quad per segment (raster/select.comp.glsl) hanging from a tile edge that
// faces a ray-cast tile down to below the tile's lowest point; clipping is off across the skirt's own plane.
layout(location = 0) in vec3 a_p;         // per instance: segment start (tile cells x, y; height in metres)
layout(location = 1) in vec3 a_q;         // segment end
uniform mat4 view_proj_rel;
out vec3 v_rel;
flat out int v_level;
noperspective out vec3 v_bary;

void main() {
    const int END[6] = int[6](0, 0, 1, 1, 0, 1);    // two triangles: (a, a', b), (b, a', b')
    const int LOW[6] = int[6](0, 1, 0, 0, 1, 1);
    int v = gl_VertexID;
    vec3 s = END[v] == 0 ? a_p : a_q;
    vec3 p = origin_rel + vec3(s.xy * spacing, s.z);
    if (LOW[v] == 1) p.z = skirt_bottom;
    int axis = a_p.x == a_q.x ? 0 : 1;              // 0: a west or east edge (x constant)
    v_rel = p;
    v_level = -1 - tile_level;                      // negative: a skirt (see tilelet.frag.glsl)
    v_bary = vec3(1.0, 0.0, 0.0);
    clip_to_tile(p, axis);
    gl_Position = view_proj_rel * vec4(p, 1.0);
}
