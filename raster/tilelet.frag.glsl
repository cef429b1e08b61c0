#version 430
#ifdef SURFACE_FROM_VERTEX
in vec2 v_uv;                  // texture coordinate and height above the origin (metres), from the vertex stage
in float v_h;
#else
#include "raster/tile_block"
#endif
in vec3 v_rel;                 // eye-relative position (metres)
flat in int v_level;
noperspective in vec3 v_bary;
uniform int mode;              // 0 texture, 1 shaded, 2 height, 3 level
uniform bool wireframe;        // darken triangle edges
uniform sampler2D tex;
uniform vec2 hrange;
out vec4 frag;
#include "shading"
#ifdef SKIRT_PROGRAM
#include "terrain_edges"
#endif
#ifdef SEAM_SKIRT
uniform bool under_pass;       // the baselines' skirts rising above their edges, for rays from under the sheet
#else
const bool under_pass = false;
#endif

vec3 level_colour(int l) {
    const vec3 pal[8] = vec3[8](vec3(0.90, 0.25, 0.20), vec3(0.95, 0.60, 0.15), vec3(0.95, 0.90, 0.25),
                                vec3(0.45, 0.80, 0.30), vec3(0.25, 0.75, 0.75), vec3(0.25, 0.45, 0.90),
                                vec3(0.55, 0.35, 0.85), vec3(0.85, 0.40, 0.70));
    return pal[l & 7];
}

void main() {
#ifdef SKIRT_PROGRAM
    // a skirt hanging below the sheet closes a crack for rays from above it; to a ray from under it, it would be
    // a wall (and a skirt rising above the sheet the other way round)
    if (ray_starts_under(v_rel) != under_pass) discard;
#endif
#ifndef SURFACE_FROM_VERTEX
    vec2 v_uv = uv_origin + (v_rel.xy - origin_rel.xy) / spacing * uv_per_cell;
    float v_h = v_rel.z - origin_rel.z;
#endif
    vec3 n = cross(dFdx(v_rel), dFdy(v_rel));
    if (n.z < 0.0) n = -n;
    // a skirt (negative level) fills the step to a neighbouring ray-cast tile's edge: shade it as the ground
    // at that edge (upward normal), not as a vertical wall
    bool skirt = v_level < 0;
    int level = skirt ? -1 - v_level : v_level;
    if (skirt) n = vec3(0.0, 0.0, 1.0);
    vec3 c;
    vec2 gx = dFdx(v_uv), gy = dFdy(v_uv);        // in uniform control flow, before the branch
    if (mode == 0) c = aniso_texture(tex, v_uv, gx, gy);
    else if (mode == 1) c = lambert(height_ramp(v_h, hrange), n);
    else if (mode == 2) c = height_ramp(v_h, hrange);
    else c = lambert(level_colour(level), n);
    if (wireframe) {
        vec3 d = fwidth(v_bary);
        vec3 a = smoothstep(vec3(0.0), 1.5 * d, v_bary);
        c = mix(vec3(0.05), c, min(min(a.x, a.y), a.z));
    }
    frag = vec4(c, 1.0);
}
