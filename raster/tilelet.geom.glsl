#version 430
#include "raster/tile_block"
#include "raster/tile_clip"
// Expand a tilelet point into its 8-triangle fan around the centre; on an edge whose neighbour is one
// level coarser the midpoint is dropped and its two triangles become one (stitching, paper Fig. 5).
layout(points) in;
layout(triangle_strip, max_vertices = 32) out;
in Tilelet {
    flat ivec4 node;
    flat int culled;
    float h[9];
#ifdef LEAN_FULL_RES
    vec2 turn;
#endif
} gs_in[];
uniform mat4 view_proj_rel;    // (world - eye) -> clip, reversed Z
uniform bool skirt_pass;        // emit only the skirts (a second pass, after the ray-cast tiles)
out vec3 v_rel;                // eye-relative position; the fragment shader derives height and uv from it
flat out int v_level;
noperspective out vec3 v_bary;

vec3 post(int c, int r) {
    int k = 1 << gs_in[0].node.z;
    ivec2 jk = gs_in[0].node.xy + ivec2(c * k, r * k);
    return origin_rel + vec3(vec2(jk) * spacing, gs_in[0].h[r * 3 + c]);
}

void vert(vec3 p, vec3 bary) {
    v_rel = p;
    v_level = tile_level + gs_in[0].node.z;
    v_bary = bary;
    clip_to_tile(p, -1);
    gl_Position = view_proj_rel * vec4(p, 1.0);
    EmitVertex();
}

// One skirt quad below the edge segment a-b, with clipping off across the skirt's own plane (it lies on the
// tile border, exactly on the clip rectangle's side).
void skirt_vert(vec3 p, int axis) {
    v_rel = p;
    v_level = -1 - tile_level - gs_in[0].node.z;   // negative: a skirt (see tilelet.frag.glsl)
    v_bary = vec3(1.0, 0.0, 0.0);
    clip_to_tile(p, axis);
    gl_Position = view_proj_rel * vec4(p, 1.0);
    EmitVertex();
}

void skirt(vec3 a, vec3 b, int axis) {
    skirt_vert(a, axis);
    skirt_vert(vec3(a.xy, skirt_bottom), axis);
    skirt_vert(b, axis);
    skirt_vert(vec3(b.xy, skirt_bottom), axis);
    EndPrimitive();
}

void edge_skirt(vec3 a, vec3 mid, vec3 b, bool dropped, int axis) {
    if (dropped) skirt(a, b, axis); else { skirt(a, mid, axis); skirt(mid, b, axis); }
}

void tri(vec3 a, vec3 b, vec3 c) {
    vert(a, vec3(1, 0, 0)); vert(b, vec3(0, 1, 0)); vert(c, vec3(0, 0, 1));
    EndPrimitive();
}

void pair(vec3 a, vec3 m, vec3 c, vec3 b) {
    vert(a, vec3(1, 0, 0)); vert(m, vec3(0, 1, 0)); vert(c, vec3(0, 0, 1)); vert(b, vec3(1, 0, 0));
    EndPrimitive();
}

void main() {
    if (gs_in[0].culled != 0) return;
    int drop = gs_in[0].node.w;   // W=1, E=2, S=4, N=8
    vec3 C = post(1, 1);
    vec3 SW = post(0, 0), S = post(1, 0), SE = post(2, 0), E = post(2, 1);
    vec3 NE = post(2, 2), N = post(1, 2), NW = post(0, 2), W = post(0, 1);
    if (skirt_pass) {                 // skirts only, drawn after the ray-cast tiles (raster.tilelets)
        if (skirt_edges == 0) return;
        int span = 2 << gs_in[0].node.z;
        ivec2 p0 = gs_in[0].node.xy;
        if ((skirt_edges & 1) != 0 && p0.x == 0) edge_skirt(SW, W, NW, (drop & 1) != 0, 0);
        if ((skirt_edges & 2) != 0 && p0.x + span == n_cells) edge_skirt(SE, E, NE, (drop & 2) != 0, 0);
        if ((skirt_edges & 4) != 0 && p0.y == 0) edge_skirt(SW, S, SE, (drop & 4) != 0, 1);
        if ((skirt_edges & 8) != 0 && p0.y + span == n_cells) edge_skirt(NW, N, NE, (drop & 8) != 0, 1);
        return;
    }
    // counter-clockwise seen from above; an edge's two triangles (C, a, m) and (C, m, b) go out as one
    // strip a, m, C, b (4 vertices instead of 6; the strip's odd triangle is (C, m, b) in GL's order)
    if (gs_in[0].node.z == 0) {
        // full resolution: the SE and NW cells (fan diagonal NW-SE) split SW-NE as the reference wherever
        // their two outer edges keep their midpoints; the SW and NE cells' fan diagonal is SW-NE already
        bool se = (drop & 6) == 0, nw = (drop & 9) == 0;
        if ((drop & 4) != 0) tri(C, SW, SE); else { tri(C, SW, S); if (!se) tri(C, S, SE); }
        if ((drop & 2) != 0) tri(C, SE, NE); else { if (!se) tri(C, SE, E); tri(C, E, NE); }
        if ((drop & 8) != 0) tri(C, NE, NW); else { tri(C, NE, N); if (!nw) tri(C, N, NW); }
        if ((drop & 1) != 0) tri(C, NW, SW); else { if (!nw) tri(C, NW, W); tri(C, W, SW); }
        vec2 turn = vec2(0.0);
#ifdef LEAN_FULL_RES
        turn = gs_in[0].turn;     // a turning cell: 4 triangles around its centre post (raster/select.comp.glsl)
#endif
        if (se && turn.x > 0.0) {
            vec3 X = vec3(0.5 * (S.xy + E.xy), mix(0.5 * (S.z + E.z), 0.5 * (C.z + SE.z), turn.x));
            pair(S, SE, X, E); pair(E, C, X, S);
        } else if (se) { tri(S, SE, E); tri(S, E, C); }
        if (nw && turn.y > 0.0) {
            vec3 X = vec3(0.5 * (W.xy + N.xy), mix(0.5 * (W.z + N.z), 0.5 * (C.z + NW.z), turn.y));
            pair(W, C, X, N); pair(N, NW, X, W);
        } else if (nw) { tri(W, C, N); tri(W, N, NW); }
    } else {
        if ((drop & 4) != 0) tri(C, SW, SE); else pair(SW, S, C, SE);
        if ((drop & 2) != 0) tri(C, SE, NE); else pair(SE, E, C, NE);
        if ((drop & 8) != 0) tri(C, NE, NW); else pair(NE, N, C, NW);
        if ((drop & 1) != 0) tri(C, NW, SW); else pair(NW, W, C, SW);
    }
}
