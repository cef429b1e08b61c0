#version 430
// Level 0 of a tile's max mipmap: texel (i, j) = max of the four corner heights of cell (i, j).
layout(local_size_x = 8, local_size_y = 8) in;
uniform sampler2D heights;                 // R32F (N+1)², row 0 = south
uniform int size;                          // N
layout(r32f, binding = 1) writeonly uniform image2D dst;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= size || p.y >= size) return;
    float a = texelFetch(heights, p, 0).r;
    float b = texelFetch(heights, p + ivec2(1, 0), 0).r;
    float c = texelFetch(heights, p + ivec2(0, 1), 0).r;
    float d = texelFetch(heights, p + ivec2(1, 1), 0).r;
    imageStore(dst, p, vec4(max(max(a, b), max(c, d))));
}
