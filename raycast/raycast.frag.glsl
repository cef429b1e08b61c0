#version 430
// One tile's ray-casting pass: the fragment of a back face of the tile's box casts the pixel-centre ray.
// Defines (set by raycast.caster): RECON, NAIVE, LOD, PREPASS, STATS, SHADOWS, MODE, OCCLUDERS, UNDER (whether any
// ray of the view may start under the terrain sheet), HF32 (tiles of float32 metres)
// MODE: 0 texture (textureGrad), 1 texture_plain (texture), 2 shaded, 3 height, 4 normal, 5 depth,
//       6 level, 7 steps
#if STATS
#extension GL_ARB_shader_ballot : enable
#extension GL_ARB_gpu_shader_int64 : enable
#extension GL_ARB_ES3_1_compatibility : enable
#endif
#include "raycast/traverse"
#include "raycast/tile_block"
#include "terrain_edges"

// --- view ---
uniform mat4 view_proj_rel;    // (world - eye) -> clip, reversed Z
uniform mat3 cam_to_world;     // eye-space direction -> world direction (columns right, up, back)
uniform vec2 ndc_scale;        // (tan(fov/2) * aspect, tan(fov/2))
uniform vec2 viewport;         // pixels
uniform float near_plane;      // metres (view depth)
uniform float far_plane;
// --- tile ---
uniform RC_SAMPLER hmap;      // R16UI (N+1)² height codes (metres = rc_height(code, dq, dq_base)); HF32: R32F metres
// (its max mipmap: the storage buffer at MIPS_BINDING, traverse.glsl)
#if OCCLUDERS
uniform sampler2D prior_depth; // reversed-Z depth of what the frame's earlier passes drew (0: nothing)
uniform vec2 depth_ab;         // (a, b): reversed-Z depth = b / view depth - a
#endif
uniform int stat_bins_x;       // 64-pixel screen bins a row (statistics slots follow the rasterizer's bins)
uniform usampler2D ids;        // pre-pass target
// --- shading ---
uniform sampler2D tex;         // terrain colour, whole terrain, mipmapped
uniform vec2 hrange;           // terrain height range (metres, relative)
uniform float heat_max;        // steps at the top of the heat map
// --- shadows: the whole terrain as one grid ---
uniform usampler2D g_hmap;
uniform usampler2D g_mmap;
uniform vec2 g_dq;
uniform int g_dq_base;
uniform int g_cells;
uniform int g_levels;
uniform vec2 g_ext;
uniform vec2 g_zr;
uniform vec2 g_spacing;        // terrain spacing east-west and north-south, metres
uniform int g_max_steps;

#if STATS
// STAT_SLOTS copies of each tile's 8 counters, STAT_WORDS uints (a cache line) apart; a fragment adds to the copy
// of its screen bin (2^STAT_BIN_SHIFT pixels a side), so rasterizer threads (which take whole bins) rarely share
// a counter line. The caster sums (and maxes) the copies; the layout comes as defines (raycast.caster).
layout(std430, binding = STATS_BINDING) buffer Stats { uint stats[]; };

#if defined(GL_ARB_shader_ballot) && defined(GL_ARB_gpu_shader_int64)
// Counters summed over the subgroup first (ballot + readInvocation), then one atomic per counter per
// subgroup from its lowest live invocation: exact counts without serialising every fragment on the atomics.
#if defined(GL_ARB_ES3_1_compatibility) || __VERSION__ >= 450
#define RC_LIVE (!gl_HelperInvocation)
#else
#define RC_LIVE true
#endif
uint rc_count(uint64_t m) { uvec2 v = unpackUint2x32(m); return uint(bitCount(v.x) + bitCount(v.y)); }

// Adds one ray (and `flag0`, `flag1` if set, and v to the sum and max) of every live invocation to
// stats[i_ray], stats[i_f0], stats[i_f1], stats[i_sum], stats[i_max] (an index < 0 is skipped).
void stats_add(int i_ray, int i_f0, bool flag0, int i_f1, bool flag1, int i_sum, int i_max, uint v) {
    uint64_t live = ballotARB(RC_LIVE);
    uint n = rc_count(live), n0 = rc_count(ballotARB(RC_LIVE && flag0)), n1 = rc_count(ballotARB(RC_LIVE && flag1));
    uint vs = 0u, vm = 0u;
    for (uint i = 0u; i < gl_SubGroupSizeARB; i++) {
        uint x = readInvocationARB(v, i);
        if (((live >> i) & 1ul) != 0ul) { vs += x; vm = max(vm, x); }
    }
    uvec2 lv = unpackUint2x32(live);
    uint first = lv.x != 0u ? uint(findLSB(lv.x)) : 32u + uint(findLSB(lv.y));
    if (gl_SubGroupInvocationARB == first) {
        atomicAdd(stats[i_ray], n);
        if (i_f0 >= 0 && n0 > 0u) atomicAdd(stats[i_f0], n0);
        if (i_f1 >= 0 && n1 > 0u) atomicAdd(stats[i_f1], n1);
        if (vs > 0u) atomicAdd(stats[i_sum], vs);
        if (i_max >= 0) atomicMax(stats[i_max], vm);
    }
}
#else
void stats_add(int i_ray, int i_f0, bool flag0, int i_f1, bool flag1, int i_sum, int i_max, uint v) {
    atomicAdd(stats[i_ray], 1u);
    if (i_f0 >= 0 && flag0) atomicAdd(stats[i_f0], 1u);
    if (i_f1 >= 0 && flag1) atomicAdd(stats[i_f1], 1u);
    atomicAdd(stats[i_sum], v);
    if (i_max >= 0) atomicMax(stats[i_max], v);
}
#endif
#endif

layout(location = 0) out vec4 frag;
layout(location = 1) out vec4 aux;   // (hit x, hit y in tile texels, hit z in metres, steps) for tests

#include "shading"

vec3 heat(float x) {
    x = clamp(x, 0.0, 1.0);
    return clamp(vec3(1.5 - abs(4.0 * x - 3.0), 1.5 - abs(4.0 * x - 2.0), 1.5 - abs(4.0 * x - 1.0)), 0.0, 1.0);
}

vec3 level_colour(int l) {
    const vec3 pal[8] = vec3[8](vec3(0.90, 0.10, 0.10), vec3(0.95, 0.55, 0.10), vec3(0.95, 0.90, 0.15),
        vec3(0.25, 0.80, 0.20), vec3(0.15, 0.75, 0.80), vec3(0.20, 0.35, 0.90), vec3(0.60, 0.25, 0.85),
        vec3(0.85, 0.85, 0.85));
    return pal[l & 7];
}

float hsample(ivec2 p) { return rc_height(texelFetch(hmap, clamp(p, ivec2(0), ivec2(n_cells)), 0).r, dq, dq_base); }

// Height gradient (metres per texel) at sample p by central differences with stride S (one-sided at borders).
vec2 central_grad(ivec2 p, int S) {
    ivec2 a = max(p - ivec2(S, 0), ivec2(0)), b = min(p + ivec2(S, 0), ivec2(n_cells));
    ivec2 c = max(p - ivec2(0, S), ivec2(0)), d = min(p + ivec2(0, S), ivec2(n_cells));
    return vec2((hsample(b) - hsample(a)) / float(b.x - a.x), (hsample(d) - hsample(c)) / float(d.y - c.y));
}

// Surface normal (world, unnormalised) at hit point Q of the cell (corner c0, size S, corner heights hc).
vec3 surface_normal(vec3 Q, ivec2 c0, int S, vec4 hc) {
    vec2 f = (Q.xy - vec2(c0)) / float(S);
    vec2 g;
#if RECON == 2
    g = (f.x >= f.y) ? vec2(hc.y - hc.x, hc.w - hc.y) : vec2(hc.w - hc.z, hc.z - hc.x);
    g /= float(S);
#elif RECON == 3
    float c = hc.x - hc.y - hc.z + hc.w;
    g = vec2(hc.y - hc.x + c * f.y, hc.z - hc.x + c * f.x) / float(S);
#else
    vec2 g00 = central_grad(c0, S), g01 = central_grad(c0 + ivec2(S, 0), S);
    vec2 g10 = central_grad(c0 + ivec2(0, S), S), g11 = central_grad(c0 + ivec2(S, S), S);
    g = mix(mix(g00, g01, f.x), mix(g10, g11, f.x), f.y);
#endif
    return vec3(-g / spacing, 1.0);
}

void main() {
#if PREPASS
    if (texelFetch(ids, ivec2(gl_FragCoord.xy), 0).r != tile_id) discard;
#endif
    vec2 ndc = gl_FragCoord.xy / viewport * 2.0 - 1.0;
    vec3 dir_eye = vec3(ndc * ndc_scale, -1.0);
    vec3 d = cam_to_world * dir_eye;              // world direction, view depth 1 per unit of t
    vec3 D = vec3(d.xy / spacing, d.z);
#if UNDER
    bool under = ray_starts_under(d);
#else
    const bool under = false;   // no ray of this view starts under the sheet (raycast.caster)
#endif
    vec3 Q; ivec2 cell; int lev; vec4 hc; int steps;
    float tmax = RC_FAR;
#if OCCLUDERS
    // what an earlier pass of the frame drew here bounds the ray: a hit behind it would fail the depth test;
    // a little past it (1e-5 of the distance, far above float rounding) the depth test still decides
    float zp = texelFetch(prior_depth, ivec2(gl_FragCoord.xy), 0).r;
    if (zp > 0.0) tmax = depth_ab.y / (zp + depth_ab.x) * 1.00001;
#endif
    // mbuf: the tile's max mipmap is its storage buffer, so the texture passed for it (hmap) is not read
    int r = rc_traverse(hmap, hmap, true, dq, dq_base, n_cells, n_levels, ext_lo, ext, zr, eye_tex, D, near_plane, tmax, 0, spacing, lod_k,
                        max_steps, outer, under, LOD == 0, Q, cell, lev, hc, steps);
#if STATS
    ivec2 bin = ivec2(gl_FragCoord.xy) >> STAT_BIN_SHIFT;
    int base = (tile_index * STAT_SLOTS + ((bin.x + bin.y * stat_bins_x) & (STAT_SLOTS - 1))) * STAT_WORDS;
    stats_add(base + 0, base + 1, r == RC_HIT, base + 4, r == RC_CAPPED, base + 2, base + 3, uint(steps));
#endif
    if (r != RC_HIT) discard;
    vec3 rel = origin_rel + vec3(Q.xy * spacing, Q.z);
    vec4 clip = view_proj_rel * vec4(rel, 1.0);
    gl_FragDepth = clip.z / clip.w;
    int S = 1 << lev;
    ivec2 c0 = cell * S;
    vec3 n = surface_normal(Q, c0, S, hc);
    float lit = 1.0;
#if SHADOWS
    vec3 L = LIGHT_DIR;
    if (dot(n, L) <= 0.0) {
        lit = 0.0;
    } else {
        int gl = tile_level + lev;
        float k = float(1 << tile_level);
        vec3 Og = vec3(g_tile_off + Q.xy * k, Q.z + 1e-3 * max(spacing.x, spacing.y) * float(S) + 0.01);
        vec3 Dg = vec3(L.xy / g_spacing, L.z);
        vec3 Qs; ivec2 cs; int ls; vec4 hs; int ssteps;
        int rs = rc_traverse(g_hmap, g_mmap, false, g_dq, g_dq_base, g_cells, g_levels, vec2(0.0), g_ext, g_zr, Og, Dg, 0.0, RC_FAR, gl, g_spacing, 0.0,
                             g_max_steps, 15, false, false, Qs, cs, ls, hs, ssteps);
        if (rs != RC_MISS) lit = 0.0;
#if STATS
        stats_add(base + 5, base + 7, rs == RC_CAPPED, -1, false, base + 6, -1, uint(ssteps));
#endif
    }
#endif
    vec2 uv = uv_off + Q.xy * uv_scale;
    vec3 c;
#if MODE == 0
    // analytic footprint: intersect the neighbouring pixel rays with the tangent plane at the hit
    vec3 nw = normalize(n);
    vec3 dx = cam_to_world * vec3(2.0 * ndc_scale.x / viewport.x, 0.0, 0.0);
    vec3 dy = cam_to_world * vec3(0.0, 2.0 * ndc_scale.y / viewport.y, 0.0);
    float pn = dot(nw, rel);
    float sx = dot(nw, d + dx), sy = dot(nw, d + dy);
    float lim = length(d) / 16.0;        // footprint stretch at most 16x (the anisotropy limit)
    sx = sign(sx) * max(abs(sx), lim); sy = sign(sy) * max(abs(sy), lim);
    vec3 px = pn / sx * (d + dx) - rel, py = pn / sy * (d + dy) - rel;
    vec2 uv_per_m = uv_scale / spacing;
    vec2 gx = px.xy * uv_per_m, gy = py.xy * uv_per_m;
    gx = gx * min(1.0, 1.0 / max(length(gx), 1e-30)); gy = gy * min(1.0, 1.0 / max(length(gy), 1e-30));
    c = aniso_texture(tex, uv, gx, gy);
#elif MODE == 1
    c = texture(tex, uv).rgb;
#elif MODE == 2
    c = lambert(height_ramp(Q.z, hrange), n);
#elif MODE == 3
    c = height_ramp(Q.z, hrange);
#elif MODE == 4
    c = normalize(n) * 0.5 + 0.5;
#elif MODE == 5
    c = vec3(clamp(1.0 - log(1.0 + length(rel)) / log(1.0 + far_plane), 0.0, 1.0));
#elif MODE == 6
    c = level_colour(tile_level + lev);
#else
    c = heat(float(steps) / heat_max);
#endif
#if SHADOWS
#if MODE == 2
    if (lit == 0.0) c = height_ramp(Q.z, hrange) * AMBIENT;
#else
    if (lit == 0.0) c *= 0.5;
#endif
#endif
    frag = vec4(c, 1.0);
    aux = vec4(Q, float(steps));
}
