#version 430
// Level l of a tile's max mipmap: max of the 2x2 texels of level l-1.
layout(local_size_x = 8, local_size_y = 8) in;
uniform int size;                          // texels a side at the destination level
layout(r32f, binding = 0) readonly uniform image2D src;
layout(r32f, binding = 1) writeonly uniform image2D dst;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= size || p.y >= size) return;
    ivec2 q = 2 * p;
    float a = imageLoad(src, q).r;
    float b = imageLoad(src, q + ivec2(1, 0)).r;
    float c = imageLoad(src, q + ivec2(0, 1)).r;
    float d = imageLoad(src, q + ivec2(1, 1)).r;
    imageStore(dst, p, vec4(max(max(a, b), max(c, d))));
}
