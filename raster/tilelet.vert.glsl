#version 430
// One point per tilelet: fetch its 3x3 post heights, geomorph the posts that vanish at the coarser
// level, and (for tiles crossing the frustum) cull the tilelet against the frustum planes.
layout(location = 0) in ivec4 a_node;     // (j0, i0) south-west post in tile cells, local level m, dropped-edge bits
layout(location = 1) in vec4 a_morph;     // morph of edge midpoints W, E, S, N
layout(location = 2) in float a_morph_c;  // morph of the centre post
uniform sampler2D heights;                // R32F (n+1)², metres relative to the terrain origin z, row 0 = south
uniform vec3 origin_rel;                  // world position of tile sample [0, 0] minus eye (z = terrain origin z - eye z)
uniform float spacing;                    // metres between tile samples
uniform bool cull;                        // test this tile's tilelets against the frustum
uniform vec4 planes[6];                   // frustum planes for eye-relative points, inside where dot >= 0
uniform bool record;                      // write per-tilelet culled flags into the SSBO
layout(std430, binding = 0) buffer CullFlags { uint culled_flag[]; };
out Tilelet {
    flat ivec4 node;
    flat int culled;
    float h[9];          // morphed heights, [row * 3 + col], row from south, col from west
} vs_out;

float H(ivec2 jk) { return texelFetch(heights, ivec2(jk.x, jk.y), 0).r; }

void main() {
    int m = a_node.z;
    int k = 1 << m;
    ivec2 p0 = a_node.xy;
    float h[9];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            h[r * 3 + c] = H(p0 + ivec2(c * k, r * k));
    float lo = h[0], hi = h[0];
    for (int q = 1; q < 9; ++q) { lo = min(lo, h[q]); hi = max(hi, h[q]); }
    // morph targets: edge midpoints toward the mean of their corners, the centre toward the mean of the
    // diagonal through the parent's centre (SW-NE for the parent's SW/NE quadrant, NW-SE otherwise)
    float hw = mix(h[3], 0.5 * (h[0] + h[6]), a_morph.x);
    float he = mix(h[5], 0.5 * (h[2] + h[8]), a_morph.y);
    float hs = mix(h[1], 0.5 * (h[0] + h[2]), a_morph.z);
    float hn = mix(h[7], 0.5 * (h[6] + h[8]), a_morph.w);
    int qx = (p0.x >> (m + 1)) & 1, qy = (p0.y >> (m + 1)) & 1;
    float diag = (qx == qy) ? 0.5 * (h[0] + h[8]) : 0.5 * (h[2] + h[6]);
    float hc = mix(h[4], diag, a_morph_c);
    h[3] = hw; h[5] = he; h[1] = hs; h[7] = hn; h[4] = hc;
    int out_flag = 0;
    if (cull) {
        vec3 bmin = origin_rel + vec3(vec2(p0) * spacing, lo);
        vec3 bmax = origin_rel + vec3(vec2(p0 + ivec2(2 * k)) * spacing, hi);
        for (int i = 0; i < 6; ++i) {
            vec3 n = planes[i].xyz;
            vec3 far_corner = vec3(n.x >= 0.0 ? bmax.x : bmin.x, n.y >= 0.0 ? bmax.y : bmin.y, n.z >= 0.0 ? bmax.z : bmin.z);
            if (dot(n, far_corner) + planes[i].w < 0.0) out_flag = 1;
        }
    }
    if (record) culled_flag[gl_VertexID] = uint(out_flag);
    vs_out.node = a_node;
    vs_out.culled = out_flag;
    vs_out.h = h;
    gl_Position = vec4(0.0, 0.0, 0.0, 1.0);
}
