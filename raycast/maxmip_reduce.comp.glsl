#version 430
// Max-mip level l + 1 of a tile (texture level l): max of the 2x2 codes of the level below.
layout(local_size_x = 8, local_size_y = 8) in;
uniform ivec2 extent;                     // texels (x, y) to fill from first (a whole level: its side)
uniform ivec2 first;                       // first texel (x, y) filled: a window after an edit, else 0
layout(r16ui, binding = 0) readonly uniform uimage2D src;
layout(r16ui, binding = 1) writeonly uniform uimage2D dst;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= extent.x || p.y >= extent.y) return;
    p += first;
    ivec2 q = 2 * p;
    uint a = imageLoad(src, q).r;
    uint b = imageLoad(src, q + ivec2(1, 0)).r;
    uint c = imageLoad(src, q + ivec2(0, 1)).r;
    uint d = imageLoad(src, q + ivec2(1, 1)).r;
    imageStore(dst, p, uvec4(max(max(a, b), max(c, d))));
}
