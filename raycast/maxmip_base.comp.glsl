#version 430
// Max-mip level 1 of a tile (texture level 0): texel (i, j) = max of the 3x3 height codes of the 2x2 cells
// (2i..2i+1, 2j..2j+1). Level 0 (one cell's four corners) is not stored: the traversal takes it from the
// heights (rc_code in traverse.glsl).
layout(local_size_x = 8, local_size_y = 8) in;
uniform usampler2D heights;                // R16UI (N+1)², row 0 = south
uniform ivec2 extent;                     // texels (x, y) to fill from first (a whole level: its side)
uniform ivec2 first;                       // first texel (x, y) filled: a window after an edit, else 0
layout(r16ui, binding = 1) writeonly uniform uimage2D dst;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= extent.x || p.y >= extent.y) return;
    p += first;
    ivec2 q = 2 * p;
    uint m = 0u;
    for (int dy = 0; dy <= 2; dy++)
        for (int dx = 0; dx <= 2; dx++)
            m = max(m, texelFetch(heights, q + ivec2(dx, dy), 0).r);
    imageStore(dst, p, uvec4(m));
}
