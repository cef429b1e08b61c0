#version 430
// A terrain brush (hybrid/terrain/edits.py) on R32F heights in place, over the touched window only.
// SNAPSHOT 1: copy the window grown by one sample (clamped to the grid) into the scratch image, so the smooth
// brush reads its neighbours' heights before the edit. SNAPSHOT 0: the brush itself, each texel from the scratch
// copy, or from itself where the brush reads its own texel only (direct: all but smooth), in the CPU
// reference's float32 order of operations (precise: no fused ops).
// The grid may be held in blocks (textures of at most the GL's size limit): a dispatch reads and writes up to
// four blocks (BLOCKS_PER_PASS), texel = sample - origin, and leaves samples outside them to other dispatches.
layout(local_size_x = 8, local_size_y = 8) in;
// the dispatch's blocks of the grid, texel (j, i) = sample (i, j) - origin, row 0 = south (unused units repeat one)
layout(r32f, binding = 0) uniform image2D heights0;
layout(r32f, binding = 2) uniform image2D heights1;
layout(r32f, binding = 3) uniform image2D heights2;
layout(r32f, binding = 4) uniform image2D heights3;
layout(r32f, binding = 1) uniform image2D scratch;     // the window grown by one sample
uniform ivec2 win0;                                    // first (column, row) of the window
uniform ivec2 win_size;                                // (columns, rows) of the window
uniform ivec2 grid;                                    // (columns, rows) of the grid
uniform ivec2 origins[4];                              // each block's first (column, row) in the grid
uniform ivec2 blocks[4];                               // each block's (columns, rows)
uniform int nblocks;                                   // blocks of this dispatch (1 to 4)
uniform vec2 centre;                                   // (cj, ci): the brush centre in fractional samples
uniform vec2 spacing;                                  // (sx, sy) metres between samples
uniform float radius2;                                 // radius² (m²)
uniform float strength;
uniform float target;                                  // flatten: metres relative to the origin z
uniform int code;                                      // 0 raise, 1 flatten, 2 smooth, 3 crater
uniform bool direct;                                   // no snapshot: each texel reads itself (all but smooth)
const float BOWL = 0.7;
const float RIM = 0.3;

float crater(float q, float depth) {
    precise float b = 1.0 - (q * q) / (BOWL * BOWL);
    precise float bowl = q < BOWL ? -depth * b : 0.0;
    precise float u = (q - BOWL) / (1.0 - BOWL);
    precise float c = 1.0 - u * u;
    precise float ring = abs(q - BOWL) < (1.0 - BOWL) ? RIM * depth * c * c : 0.0;
    return bowl + ring;
}

// Whether the dispatch's block k holds grid sample g (column, row), and g's texel there (blocks do not overlap).
bool holds(int k, ivec2 g, out ivec2 texel) {
    texel = g - origins[k];
    return k < nblocks && all(greaterThanEqual(texel, ivec2(0))) && all(lessThan(texel, blocks[k]));
}

float load_height(int k, ivec2 t) {
    if (k == 0) return imageLoad(heights0, t).r;
    if (k == 1) return imageLoad(heights1, t).r;
    if (k == 2) return imageLoad(heights2, t).r;
    return imageLoad(heights3, t).r;
}

void store_height(int k, ivec2 t, float h) {
    if (k == 0) imageStore(heights0, t, vec4(h));
    else if (k == 1) imageStore(heights1, t, vec4(h));
    else if (k == 2) imageStore(heights2, t, vec4(h));
    else imageStore(heights3, t, vec4(h));
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
#if SNAPSHOT
    if (p.x >= win_size.x + 2 || p.y >= win_size.y + 2) return;
    ivec2 g = clamp(win0 - 1 + p, ivec2(0), grid - 1), src;
    for (int k = 0; k < 4; k++) {
        if (holds(k, g, src)) {
            imageStore(scratch, p, vec4(load_height(k, src)));
            break;
        }
    }
#else
    if (p.x >= win_size.x || p.y >= win_size.y) return;
    ivec2 texel;
    int k = 0;
    while (k < 4 && !holds(k, win0 + p, texel)) k++;
    if (k == 4) return;                                 // another dispatch's blocks hold it
    ivec2 s = p + 1;                                    // this sample in the scratch image
    precise float old = direct ? load_height(k, texel) : imageLoad(scratch, s).r;
    vec2 ij = vec2(win0 + p);
    precise float dx = (ij.x - centre.x) * spacing.x;
    precise float dy = (ij.y - centre.y) * spacing.y;
    precise float t = (dx * dx + dy * dy) / radius2;
    if (t >= 1.0) return;
    precise float w = (1.0 - t) * (1.0 - t);
    precise float h;
    if (code == 0) {
        h = old + strength * w;
    } else if (code == 1) {
        h = old + (target - old) * (strength * w);
    } else if (code == 2) {
        precise float total = 0.0;
        for (int di = -1; di <= 1; di++)                // fixed 3x3: rows south to north, as the CPU sums
            for (int dj = -1; dj <= 1; dj++)
                total += imageLoad(scratch, s + ivec2(dj, di)).r;
        h = old + (total / 9.0 - old) * (strength * w);
    } else {
        h = old + crater(sqrt(t), strength);
    }
    store_height(k, texel, h);
#endif
}
