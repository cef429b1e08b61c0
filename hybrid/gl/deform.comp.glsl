#version 430
// Procedural deformations (hybrid/terrain/deform.py) composed over a window of R32F heights: each texel set to
// its base height plus every deformation's displacement at the current time, in the order they were added, in
// the CPU reference's float32 order of operations (precise: no fused ops). The loop runs over at most MAX_DEF.
layout(local_size_x = 8, local_size_y = 8) in;
layout(r32f, binding = 0) uniform image2D heights;     // the grid, texel (j, i) = sample (i, j), row 0 = south
layout(r32f, binding = 1) uniform image2D base;        // the grid's base heights (every brush, no deformation)
uniform ivec2 win0;                                    // first (column, row) of the window (inside the block)
uniform ivec2 origin;                                  // the block's first (column, row): texel = sample - origin
uniform ivec2 win_size;                                // (columns, rows) of the window
uniform vec2 spacing;                                  // (sx, sy) metres between samples
uniform int count;                                     // deformations in the arrays (<= MAX_DEF)
uniform vec4 disc[MAX_DEF];                            // (cj, ci, radius², code 0 wave / 1 uplift)
uniform vec4 motion[MAX_DEF];                          // (amplitude m or rate m/s, wavelength m, speed m/s, tau s)
const float TWO_PI = 6.2831855;

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= win_size.x || p.y >= win_size.y) return;
    precise float h = imageLoad(base, win0 + p - origin).r;
    vec2 ij = vec2(win0 + p);
    for (int k = 0; k < MAX_DEF; k++) {
        if (k >= count) break;
        precise float dx = (ij.x - disc[k].x) * spacing.x;
        precise float dy = (ij.y - disc[k].y) * spacing.y;
        precise float d2 = dx * dx + dy * dy;
        precise float t = d2 / disc[k].z;
        if (t >= 1.0) continue;
        precise float w = (1.0 - t) * (1.0 - t);
        float tau = motion[k].w;
        if (disc[k].w > 0.5) {
            precise float up = motion[k].x * tau * w;
            h = h + up;
            continue;
        }
        precise float d = sqrt(d2);
        precise float front = motion[k].z * tau;
        if (d >= front) continue;
        precise float phase = (d - front) / motion[k].y;
        phase = phase - floor(phase);
        precise float wave = motion[k].x * w * sin(TWO_PI * phase);
        h = h + wave;
    }
    imageStore(heights, win0 + p - origin, vec4(h));
}
