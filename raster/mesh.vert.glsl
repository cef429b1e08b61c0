#version 430
#include "raster/tile_block"
#include "raster/tile_clip"
// Baseline meshes (full-resolution triangle list, decimated TIN): tile-local vertex positions in metres.
// With SEAM_SKIRT it draws their skirts (raster.mesh_skirts): the same positions, so a skirt's upper edge is the
// mesh's border edge bit for bit; lower vertices hang skirt_depth metres below it (rise above it where negative:
// the pass for rays from under the sheet).
in vec3 a_pos;                 // (x, y) metres from tile sample [0, 0], z metres above the terrain origin z
#ifdef SEAM_SKIRT
in vec2 a_skirt;               // side (0 W, 1 E, 2 S, 3 N); 1 on the lower edge, 0 on the upper
uniform vec4 skirt_depth;      // metres each side's skirt hangs below its edge (W, E, S, N); negative: rises
#endif
uniform mat4 view_proj_rel;
out vec3 v_rel;                // eye-relative position; the fragment shader derives height and uv from it
flat out int v_level;
noperspective out vec3 v_bary;
void main() {
    vec3 p = origin_rel + a_pos;
#ifdef SEAM_SKIRT
    int side = int(a_skirt.x);
    p.z -= a_skirt.y * skirt_depth[side];
    v_level = -1 - tile_level;                      // negative: a skirt (see tilelet.frag.glsl)
    clip_to_tile(p, side < 2 ? 0 : 1);              // a skirt lies on its side's line: that axis stays open
#else
    v_level = tile_level;
    clip_to_tile(p, -1);
#endif
    v_rel = p;
    v_bary = vec3(1.0);
    gl_Position = view_proj_rel * vec4(p, 1.0);
}
