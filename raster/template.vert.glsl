#version 430
// The path without a geometry shader: an instanced 8-triangle template, one instance per selected leaf
// (raster/select.comp.glsl): the fan around the leaf's centre, where a dropped edge's two triangles become
// one and a degenerate one (stitching). In full-resolution leaves (local level 0) the south-east and
// north-west cells, whose fan diagonal runs NW-SE, are split SW-NE as the reference wherever their two
// outer edges keep their midpoints; the other two cells' fan diagonal is SW-NE already.
layout(location = 0) in ivec4 a_node;     // per instance: (j0, i0) in tile cells, local level m, dropped edges
layout(location = 1) in vec4 a_h0;        // post heights 0..3 ([row * 3 + col], row from south), metres
layout(location = 2) in vec4 a_h1;        // post heights 4..7
layout(location = 3) in float a_h8;       // post height 8
uniform vec3 origin_rel;                  // tile sample [0, 0] minus eye, metres
uniform float spacing;                    // metres between tile samples
uniform mat4 view_proj_rel;               // (world - eye) -> clip, reversed Z
uniform vec4 clip_rel;                    // tile.clip minus eye: x0, y0, x1, y1
uniform int tile_level;                   // pyramid level of the tile
out vec3 v_rel;                           // eye-relative position; the fragment shader derives height and uv
flat out int v_level;
noperspective out vec3 v_bary;
out float gl_ClipDistance[4];

// posts [row * 3 + col]; counter-clockwise seen from above
const int FAN[24] = int[24](4, 0, 1, 4, 1, 2,  4, 2, 5, 4, 5, 8,  4, 8, 7, 4, 7, 6,  4, 6, 3, 4, 3, 0);
const int SE_CELL[6] = int[6](1, 2, 5, 1, 5, 4);    // replaces fan triangles 1 and 2
const int NW_CELL[6] = int[6](3, 4, 7, 3, 7, 6);    // replaces fan triangles 5 and 6
const int EDGE_BIT[4] = int[4](4, 2, 8, 1);     // fan triangle pairs: S, E, N, W
const int EDGE_END[4] = int[4](2, 8, 6, 0);     // each edge's second corner

void main() {
    int v = gl_VertexID;
    int m = a_node.z, drop = a_node.w;
    int t = v / 3, e = t / 2;
    int post = FAN[v];
    if (m == 0 && (t == 1 || t == 2) && (drop & 6) == 0) post = SE_CELL[v - 3];        // S and E kept
    else if (m == 0 && (t == 5 || t == 6) && (drop & 9) == 0) post = NW_CELL[v - 15];  // N and W kept
    else if ((drop & EDGE_BIT[e]) != 0) {
        bool mid = (post & 1) == 1;                          // posts 1, 3, 5, 7 are edge midpoints
        if ((t & 1) == 0 && mid) post = EDGE_END[e];         // (C, a, m) -> (C, a, b)
        else if ((t & 1) == 1) post = 4;                     // (C, m, b) -> degenerate
    }
    float h[9] = float[9](a_h0.x, a_h0.y, a_h0.z, a_h0.w, a_h1.x, a_h1.y, a_h1.z, a_h1.w, a_h8);
    int k = 1 << m;
    ivec2 jk = a_node.xy + ivec2((post % 3) * k, (post / 3) * k);
    vec3 p = origin_rel + vec3(vec2(jk) * spacing, h[post]);
    v_rel = p;
    v_level = tile_level + m;
    int c = v % 3;
    v_bary = vec3(c == 0, c == 1, c == 2);
    gl_ClipDistance[0] = p.x - clip_rel.x;
    gl_ClipDistance[1] = p.y - clip_rel.y;
    gl_ClipDistance[2] = clip_rel.z - p.x;
    gl_ClipDistance[3] = clip_rel.w - p.y;
    gl_Position = view_proj_rel * vec4(p, 1.0);
}
