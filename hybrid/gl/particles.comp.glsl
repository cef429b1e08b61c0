#version 430
// Particles falling and bouncing on a terrain's heights (hybrid/gl/particles.py): one invocation a particle and
// a capped number of sub-steps a frame. Each reads the GPU heights the brush pass edits (hybrid/gl/brush.py), so a
// raise pushes resting particles up and a crater lets them fall. Positions are metres relative to the terrain's
// origin (x east, y north, z up); the extent's walls mirror a particle back, and one that is no longer finite
// starts again from its spawn point.
layout(local_size_x = 64) in;
layout(r32f, binding = 0) readonly uniform image2D heights;   // texel (j, i) = sample (i, j), row 0 = south
layout(std430, binding = 0) buffer Positions { vec4 pos[]; };         // xyz metres, w unused
layout(std430, binding = 1) buffer Velocities { vec4 vel[]; };        // xyz metres a second
layout(std430, binding = 2) readonly buffer Homes { vec4 home[]; };   // spawn points, as pos
uniform int count;
uniform ivec2 grid;            // (columns, rows) of samples
uniform vec2 spacing;          // (sx, sy) metres between samples
uniform float dt;              // seconds a sub-step
uniform int substeps;          // sub-steps this frame, at most MAX_SUBSTEPS
uniform float gravity;         // m/s² downward
uniform float restitution;     // share of the normal speed kept by a bounce
uniform float friction;        // share of the tangential speed lost at each contact
uniform float clearance;       // metres between the surface and a particle's centre

float sample_at(ivec2 t) {
    return imageLoad(heights, clamp(t, ivec2(0), grid - 1)).r;
}

// The surface (metres, relative to the origin z) at local (x, y) metres and its upward unit normal:
// the reference's triangles (SW-NE diagonal) or, with BILINEAR, the bilinear patch.
float surface(vec2 xy, out vec3 n) {
    vec2 u = clamp(xy / spacing, vec2(0.0), vec2(grid - 1));
    ivec2 c = min(ivec2(floor(u)), max(grid - 2, ivec2(0)));
    vec2 f = u - vec2(c);
    float h00 = sample_at(c), h01 = sample_at(c + ivec2(1, 0));
    float h10 = sample_at(c + ivec2(0, 1)), h11 = sample_at(c + ivec2(1, 1));
#if BILINEAR
    float du = mix(h01 - h00, h11 - h10, f.y);
    float dv = mix(h10 - h00, h11 - h01, f.x);
    float h = mix(mix(h00, h01, f.x), mix(h10, h11, f.x), f.y);
#else
    bool lower = f.x >= f.y;                            // south-east of the diagonal
    float du = lower ? h01 - h00 : h11 - h10;
    float dv = lower ? h11 - h01 : h10 - h00;
    float h = h00 + f.x * du + f.y * dv;
#endif
    n = normalize(vec3(-du / spacing.x, -dv / spacing.y, 1.0));
    return h;
}

// Mirror a coordinate back into [0, hi], losing speed as a bounce does.
void wall(inout float p, inout float v, float hi) {
    if (p < 0.0 || p > hi) {
        v = -v * restitution;
        p = clamp(p, 0.0, hi);
    }
}

// Push p above the surface; a particle moving into it bounces off along the normal.
void contact(inout vec3 p, inout vec3 v) {
    vec3 n;
    float h = surface(p.xy, n) + clearance;
    if (p.z < h) {
        p.z = h;
        float vn = dot(v, n);
        if (vn < 0.0)
            v = (v - vn * n) * (1.0 - friction) - restitution * vn * n;
    }
}

void main() {
    uint k = gl_GlobalInvocationID.x;
    if (k >= uint(count)) return;
    vec3 p = pos[k].xyz;
    vec3 v = vel[k].xyz;
    vec2 ext = vec2(grid - 1) * spacing;
    for (int s = 0; s < MAX_SUBSTEPS; s++) {           // capped: substeps <= MAX_SUBSTEPS
        if (s >= substeps) break;
        v.z -= gravity * dt;
        p += v * dt;
        wall(p.x, v.x, ext.x);
        wall(p.y, v.y, ext.y);
        contact(p, v);
    }
    if (any(isnan(p)) || any(isinf(p)) || any(isnan(v)) || any(isinf(v))) {
        p = home[k].xyz;                                // respawned where it started, at rest
        v = vec3(0.0);
    }
    contact(p, v);                                      // above the surface now, sub-steps or none
    pos[k] = vec4(p, 0.0);
    vel[k] = vec4(v, 0.0);
}
