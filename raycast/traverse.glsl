// Height-field ray traversal over a maximum mipmap (Dick et al. 2009, sections 3.1-3.2), shared by primary
// and shadow rays. Texel space: x, y in texels of the grid (sample (i, j) at (j, i)), z in metres relative to
// the terrain's origin z; a ray is P(t) = O + t * D. The grid has N cells a side (N a power of two), the real
// terrain drawn covers [elo.x, ext.x] x [elo.y, ext.y] of it (elo = 0 but for a tile drawn for a missing finer
// one: that tile's rectangle) and heights lie in [zr.x, zr.y]. Max-mip level l texel (i, j)
// bounds the cells [i*2^l, (i+1)*2^l) x [j*2^l, (j+1)*2^l). Texel space scales world x and y separately (metres
// per texel spacing.x east-west, spacing.y north-south): a world ray E + t d becomes O + t D with
// D = (d.x / spacing.x, d.y / spacing.y, d.z), so t stays the world ray parameter and hit depths stay metres.
//
// Heights are 16-bit codes (R16UI, hybrid/tiles/quantize.py): metres = float32(dq.x + dq.y * (q + dqb)). The
// max mipmap holds levels 1..log2 N (rc_code: a tile's in a storage buffer, the shadow grid's in a texture). A
// level-0 step reads its parent's level-1 code (or the largest of the cell's four corner codes, where exact0:
// rc_code). Maxima are taken on codes: dequantisation is monotone. The traversal runs in code space, z measured in codes
// (z_c = (z - dq.x) / dq.y - dqb), so a code is its own height and neither a step nor a cell test decodes one:
// the map is affine in z, so it keeps the ray straight, its parameter t and every fraction along a segment.
// Only the hit and its cell's corners go back to metres. On a SIMD rasterizer a branch compiled into the loop
// runs for every lane, so each step makes one fetch and one conversion.
//
// Defines: RECON 0 planes (piecewise constant: a cell is a box of its max-mip height), 1 linear approximation
// planes (Qu 3.1), 2 triangle mesh with the SW-NE diagonal (Qu 3.2), 3 bilinear patch (analytic);
// NAIVE 1 = step level-0 (or lmin) texels only; LOD 1 = stop descending where the projected texel is small.

// HF32 1: the tile holds float32 metres (R32F) in place of codes: a code is its height, and its bound is itself.
#if HF32
#define RC_SAMPLER sampler2D
#define RC_CODE float
#define RC_CODE4 vec4
#else
#define RC_SAMPLER usampler2D
#define RC_CODE uint
#define RC_CODE4 uvec4
#endif

#define RC_MISS 0
#define RC_HIT 1
#define RC_CAPPED 2
#define RC_FAR 1e30

// Metres (relative to the terrain's origin z) of a height code, in float32: offset + step * (q + base), within
// a float32 unit or two of the stored heights (the shading's gradients read it; the traversal reads codes).
float rc_height(uint q, vec2 dq, int dqb) { return dq.x + dq.y * float(int(q) + dqb); }
float rc_height(float h, vec2 dq, int dqb) { return h; }

// A tile's max mipmap is a storage buffer (raycast/mip_buffer.py): max-mip levels 1..log2 N one after
// another, each row by row, level l starting at texel (N² - 4 (N >> l)²) / 3; uint16 codes two to a word (the low
// half first), or float32 metres (HF32). A buffer read is an index and a load where a texture fetch at a per-lane
// level computes that level's offset and size first. The shadow rays' whole-terrain grid keeps its max mipmap in a
// texture (it can outgrow a storage block), whose level k is max-mip level k + 1.
#if HF32
layout(std430, binding = MIPS_BINDING) readonly buffer TileMips { float tile_mips[]; };
float rc_mip_texel(int i) { return tile_mips[i]; }
#else
layout(std430, binding = MIPS_BINDING) readonly buffer TileMips { uint tile_mips[]; };
uint rc_mip_texel(int i) { return (tile_mips[i >> 1] >> ((i & 1) << 4)) & 0xFFFFu; }
#endif

// The 2x2 height texels around corner c + 1 in one gather: a level-0 cell's four corners (cell c), in the gather's
// order for the footprint (x0, x1) x (y0, y1): (x0, y1), (x1, y1), (x1, y0), (x0, y0).
RC_CODE4 rc_gather(RC_SAMPLER hmap, ivec2 c) {
    return textureGather(hmap, (vec2(c) + 1.0) / vec2(textureSize(hmap, 0)), 0);
}

// An upper bound (max-mip code) of the heights of texel ri at level l of an N-cell grid: its max-mip texel, read
// from the tile's buffer where `mbuf` (a compile-time constant of the call), else from texture mmap; for a
// level-0 cell its level-1 parent's (one read a step: the cell's own corners are read where the ray enters its
// parent's box), or, where `exact0`, the largest of its four corner codes. Used for every bound the traversal
// reads (steps and LOD parents).
RC_CODE rc_code(RC_SAMPLER hmap, RC_SAMPLER mmap, bool mbuf, int N, int l, ivec2 ri, bool exact0) {
    // exact0 is a compile-time false in the caster's common variant (no planes, no ray under the sheet), so
    // the gather is compiled out there: a SIMD rasterizer runs a branch for every lane whenever it is compiled
    if (l == 0 && exact0) {
        RC_CODE4 c = rc_gather(hmap, ri);   // the cell's four corners
        return max(max(c.x, c.y), max(c.z, c.w));
    }
    int lp = max(l, 1);
    ivec2 rp = l == 0 ? ri >> 1 : ri;
    if (mbuf) {
        int m = N >> lp;
        return rc_mip_texel((N * N - 4 * m * m) / 3 + rp.y * m + rp.x);
    }
    return texelFetch(mmap, rp, lp - 1).r;
}

// An upper bound (metres) of the height of code q in float32 arithmetic, for the level of detail's distances
// (which take metres): the float evaluation is within a few float32 units of the stored height, and the margin
// (5 units of the terms' size) covers that.
float rc_bound(uint q, vec2 dqf, int dqb) {
    float k = float(int(q) + dqb);
    float v = dqf.x + dqf.y * k;
    return v + 6e-7 * (abs(dqf.x) + abs(dqf.y * k));
}
float rc_bound(float h, vec2 dqf, int dqb) { return h; }

// A texel's value as a float: a code (exact: codes are below 2^16; the signed conversion is one instruction
// where an unsigned one is not), or float32 metres as they are (HF32).
float rc_val(uint q) { return float(int(q)); }
float rc_val(float h) { return h; }

// The corner codes (h00, h01 east, h10 north, h11) of the cell at corner c0 of size S, as floats. Where `unit`
// (a compile-time constant of the call: every final cell of the traversal is a level-0 cell, S == 1) the four are
// the 2x2 texels around the cell's north-east corner and one gather reads them, in place of four fetches.
vec4 rc_corners(RC_SAMPLER hmap, ivec2 c0, int S, bool unit) {
    if (unit) {
        RC_CODE4 c = rc_gather(hmap, c0);
        return vec4(rc_val(c.w), rc_val(c.z), rc_val(c.x), rc_val(c.y));
    }
    return vec4(rc_val(texelFetch(hmap, c0, 0).r), rc_val(texelFetch(hmap, c0 + ivec2(S, 0), 0).r),
                rc_val(texelFetch(hmap, c0 + ivec2(0, S), 0).r), rc_val(texelFetch(hmap, c0 + ivec2(S, S), 0).r));
}

// Offset of the point at fraction f of a cell from the interpolating surface of its corners (bilinear).
float rc_bilin(vec4 hc, vec2 f) {
    return mix(mix(hc.x, hc.y, f.x), mix(hc.z, hc.w, f.x), f.y);
}

// Height of the triangle (lower: fx >= fy, else upper) at fraction f; hc = (h00, h01, h10, h11).
float rc_tri(vec4 hc, vec2 f, bool lower) {
    return lower ? hc.x + f.x * (hc.y - hc.x) + f.y * (hc.w - hc.y)
                 : hc.x + f.y * (hc.z - hc.x) + f.x * (hc.w - hc.z);
}

// First hit on the segment A -> B (real texel space) inside the cell at corner c0 of size S: fraction u in
// [0, 1], or -1. hc are the corner heights (h00, h01 east, h10 north, h11), H the cell's max-mip height.
float rc_cell_hit(vec3 A, vec3 B, vec2 c0, float S, vec4 hc, float H) {
#if RECON == 0
    if (A.z <= H) return 0.0;
    if (B.z <= H) return (H - A.z) / (B.z - A.z);
    return -1.0;
#else
    vec2 fa = (A.xy - c0) / S, fb = (B.xy - c0) / S;
#if RECON == 1
    float d1 = A.z - rc_bilin(hc, fa), d2 = B.z - rc_bilin(hc, fb);
    if (d1 <= 0.0) return 0.0;
    if (d2 <= 0.0) return d1 / (d1 - d2);
    return -1.0;
#elif RECON == 2
    float ga = fa.x - fa.y, gb = fb.x - fb.y;
    float ud = (ga * gb < 0.0) ? ga / (ga - gb) : 1.0;
    bool lower = mix(ga, gb, 0.5 * ud) >= 0.0;
    float d0 = A.z - rc_tri(hc, fa, lower);
    if (d0 <= 0.0) return 0.0;
    vec2 fd = mix(fa, fb, ud);
    float zd = mix(A.z, B.z, ud);
    float dd = zd - rc_tri(hc, fd, lower);
    if (dd <= 0.0) return ud * d0 / (d0 - dd);
    if (ud < 1.0) {
        float dd2 = zd - rc_tri(hc, fd, !lower);
        if (dd2 <= 0.0) return ud;
        float d1 = B.z - rc_tri(hc, fb, !lower);
        if (d1 <= 0.0) return ud + (1.0 - ud) * dd2 / (dd2 - d1);
    }
    return -1.0;
#else
    // precise: the quadratic's coefficients cancel, so whether a compiler fuses their products into
    // multiply-adds would move the root; every variant of the shader evaluates them the same way
    precise vec2 df = fb - fa;
    precise float a = hc.y - hc.x, b = hc.z - hc.x, c = hc.x - hc.y - hc.z + hc.w;
    precise float k0 = A.z - (hc.x + a * fa.x + b * fa.y + c * fa.x * fa.y);
    if (k0 <= 0.0) return 0.0;
    precise float k1 = (B.z - A.z) - (a * df.x + b * df.y + c * (fa.x * df.y + fa.y * df.x));
    precise float k2 = -c * df.x * df.y;
    precise float dend = k0 + k1 + k2;
    if (abs(k2) <= 1e-6 * (abs(k1) + abs(k0))) {
        if (dend <= 0.0) return k0 / (k0 - dend);
        return -1.0;
    }
    float disc = k1 * k1 - 4.0 * k2 * k0;
    if (disc < 0.0) return -1.0;
    float sq = sqrt(disc);
    float q = -0.5 * (k1 + (k1 >= 0.0 ? sq : -sq));
    float u = RC_FAR;
    float r1 = q / k2;
    if (r1 >= 0.0 && r1 <= 1.0) u = r1;
    if (q != 0.0) { float r2 = k0 / q; if (r2 >= 0.0 && r2 <= 1.0) u = min(u, r2); }
    if (u <= 1.0) return u;
    if (dend <= 0.0) return 1.0;
    return -1.0;
#endif
#endif
}

// Level-of-detail stop (coherent per patch): a level-l texel is final when a texel of its size, seen from
// the eye at the nearest point of the texel's box, spans at most tau pixels: size_m * K <= tau * distance.
// Om: eye in the mirrored texel space; spacing: metres per texel in x and y; lod_k = (the larger spacing) * K / tau
// (metres), so a texel's size is its longer side.
bool rc_lod_final(int l, vec2 ij, float H, vec3 Om, float zlo, vec2 spacing, float lod_k) {
    float s = float(1 << l);
    vec2 lo = ij * s, hi = lo + s;
    vec2 dxy = max(max(lo - Om.xy, Om.xy - hi), 0.0) * spacing;
    float dz = max(max(zlo - Om.z, Om.z - H), 0.0);
    return s * lod_k <= length(vec3(dxy, dz));
}

// Whether a ray leaving texel ij (through its x side where cx, its y side where cy) climbs a level: where the
// border it crosses is also its parent's, so the parent it climbs to is one it has not tested.
bool rc_climbs(vec2 ij, bool cx, bool cy) {
    return (cx && ((int(ij.x) + 1) & 1) == 0) || (cy && ((int(ij.y) + 1) & 1) == 0);
}

// Cast one ray through the grid (height codes hmap, max mipmap in the tile's buffer where mbuf, else texture mmap;
// dequantised by dq, dqb): returns RC_MISS, RC_HIT or RC_CAPPED. On a hit, hit is the point (real texel
// space), cell the hit texel (x, y) at level `level`, hc its corner heights. tmin: smallest ray parameter
// (near plane); tmax: largest (RC_FAR: none; a ray stopped there is a miss); lmin: the finest level to descend to; steps: texels visited. under: the ray starts under the
// terrain sheet (hybrid/gl/edges.glsl): its hit is where it first comes up through the surface (the sheet's
// underside, as the two-sided reference draws it), found by stepping every lmin texel (no LOD). unit_cells: a
// compile-time constant, true where lmin is 0 and there is no LOD, so every cell tested is a level-0 cell.
int rc_traverse(RC_SAMPLER hmap, RC_SAMPLER mmap, bool mbuf, vec2 dq, int dqb, int N, int LMAX, vec2 elo, vec2 ext, vec2 zr,
                vec3 O, vec3 D,
                float tmin, float tmax, int lmin, vec2 spacing, float lod_k, int max_steps, int outer,
                bool under, bool unit_cells, out vec3 hit, out ivec2 cell, out int level, out vec4 hc, out int steps) {
    steps = 0; level = 0; cell = ivec2(0); hit = vec3(0.0); hc = vec4(0.0);
    // to code space (z only; the step is > 0: a flat tile has step 1); the LOD's distances keep metres
    vec2 dqf = dq;
    float zsc = 1.0 / dqf.y, zb = float(dqb);
    float Oz_m = O.z;
    vec2 zr_m = zr;
    O.z = (O.z - dqf.x) * zsc - zb;
    D.z *= zsc;
    zr = (zr - dqf.x) * zsc - zb;
    // entry into the box; `face` is the box side the ray enters through (EDGE_W/E/S/N bits, 0 for the top,
    // the bottom or a start inside at tmin). The terrain is a sheet without side walls: a ray on the wrong
    // side of the surface where it enters the box through the terrain's outer boundary, or (under) through
    // the top or at tmin, is not a hit there. Entering through an interior side on the wrong side of this
    // tile's surface is a hit (a wall): the ray met the neighbour's surface first (the nearer hit wins) or
    // passed through a crack between tiles of different levels (the wall fills it).
    float t0 = tmin, t1 = tmax;
    int face = 0;
    bool zentry = false;   // entered through the bottom or top face: put P exactly on it (no rounding above/below)
    if (D.x != 0.0) {
        float ta = (elo.x - O.x) / D.x, tb = (ext.x - O.x) / D.x;
        if (min(ta, tb) > t0) { t0 = min(ta, tb); face = D.x > 0.0 ? 1 : 2; }
        t1 = min(t1, max(ta, tb));
    } else if (O.x < elo.x || O.x > ext.x) return RC_MISS;
    if (D.y != 0.0) {
        float ta = (elo.y - O.y) / D.y, tb = (ext.y - O.y) / D.y;
        if (min(ta, tb) > t0) { t0 = min(ta, tb); face = D.y > 0.0 ? 4 : 8; }
        t1 = min(t1, max(ta, tb));
    } else if (O.y < elo.y || O.y > ext.y) return RC_MISS;
    float t1_side = t1;
    if (D.z != 0.0) {
        float ta = (zr.x - O.z) / D.z, tb = (zr.y - O.z) / D.z;
        if (min(ta, tb) > t0) { t0 = min(ta, tb); face = 0; zentry = true; }
        t1 = min(t1, max(ta, tb));
    } else if (O.z < zr.x || O.z > zr.y) return RC_MISS;
    // A descending ray that reaches an interior side below the whole box went under the surface on that edge,
    // which both tiles share: the neighbour's surface is nearer, and where the neighbour left the pixel empty
    // (a raster edge rounds to 1/256 px and can miss a pixel whose ray meets the surface just before it) the
    // wall there fills it, as it does above the box's bottom.
    if (t0 > t1 && !under && D.z < 0.0 && face != 0 && (face & outer) == 0 && t0 <= t1_side && O.z + t0 * D.z < zr.x)
        t1 = t0;
    if (t0 > t1) return RC_MISS;
    bool no_entry_hit = (face & outer) != 0 || (under && face == 0 && !(zentry && D.z > 0.0));
    bool moved = false;
    float Nf = float(N);
    bool mx = D.x < 0.0, my = D.y < 0.0;
    vec3 P = O + t0 * D;
    if (zentry) P.z = D.z > 0.0 ? zr.x : zr.y;
    vec3 Om = vec3(O.xy, Oz_m);
    if (mx) { P.x = Nf - P.x; D.x = -D.x; Om.x = Nf - O.x; }
    if (my) { P.y = Nf - P.y; D.y = -D.y; Om.y = Nf - O.y; }
    vec2 lo = vec2(mx ? Nf - ext.x : elo.x, my ? Nf - ext.y : elo.y);
    vec2 hi = vec2(mx ? Nf - elo.x : ext.x, my ? Nf - elo.y : ext.y);
    P.xy = clamp(P.xy, lo, hi);
    // every exit is computed from the entry point P0 (no accumulated rounding): X = P0 + s * D
    vec3 P0 = P;
    float sP = 0.0;
    float s_max = tmax - t0;                // past it the ray is behind what the frame already drew there
    int ltop = max(LMAX - 1, 0);
    lmin = min(lmin, ltop);
#if NAIVE
    int l = lmin;
#else
    // start at the level whose texels are about as wide as the ray travels across the box's height range: a
    // steep ray starts low (it would descend anyway), a grazing one high (it skips far in few steps)
    float span = D.z != 0.0 ? (zr.y - zr.x) / abs(D.z) * length(D.xy) : Nf;
    int l = under ? lmin : clamp(int(floor(log2(max(span, 1.0)))), lmin, ltop);
#endif
    // Two nested loops: the inner one only steps texels (cheap: one max-mip fetch a step) and stops at a
    // level-0 (final) texel whose box the ray enters; the outer one intersects that cell's surface. On a SIMD
    // rasterizer every statement of a loop body runs for all lanes, so the costly cell test (four height
    // fetches and the reconstruction) is kept out of the per-step body. Same steps, same order, same floats.
    float s, H, dt;
    // a level-0 step tests the cell's own bound where the bound is the surface (planes) or the ray climbs
    // through the sheet from below (its hit is the first cell where it is no longer under the surface)
    bool exact0 = RECON == 0 || under;
    // per ray: the reciprocal direction and the exit through the bottom or top of the box, which every step shares
    vec2 invD = vec2(D.x > 0.0 ? 1.0 / D.x : 0.0, D.y > 0.0 ? 1.0 / D.y : 0.0);
    float dtz = D.z < 0.0 ? (zr.x - P0.z) / D.z : (D.z > 0.0 ? (zr.y - P0.z) / D.z : RC_FAR);
    float invDz = D.z < 0.0 ? 1.0 / D.z : 0.0;     // the descent's division, as a product
    float ztop = D.z >= 0.0 ? zr.y : RC_FAR;        // a rising ray above the box has left it
    RC_CODE mc = RC_CODE(0);
    vec2 ij, e;
    ivec2 ri;
    bool cx, cy, cz;
    vec3 X;
    for (;;) {
        bool cand = false;
        while (steps < max_steps) {
            if (P.x >= hi.x || P.y >= hi.y || P.z > ztop || sP > s_max) return RC_MISS;
            steps++;
            s = float(1 << l);
            ij = floor(ldexp(P.xy, ivec2(-l)));
            int nl = N >> l;
#if LOD
            // coherent LOD: a texel whose parent is already final belongs to the parent's level
            while (!under && l < ltop) {
                vec2 pij = floor(ij * 0.5);
                ivec2 pri = ivec2(mx ? (nl >> 1) - 1 - int(pij.x) : int(pij.x), my ? (nl >> 1) - 1 - int(pij.y) : int(pij.y));
                float PH = rc_bound(rc_code(hmap, mmap, mbuf, N, l + 1, pri, false), dqf, dqb);
                if (!rc_lod_final(l + 1, pij, PH, Om, zr_m.x, spacing, lod_k)) break;
                l++; s *= 2.0; ij = pij; nl >>= 1;
            }
#endif
            ri = ivec2(mx ? nl - 1 - int(ij.x) : int(ij.x), my ? nl - 1 - int(ij.y) : int(ij.y));
            mc = rc_code(hmap, mmap, mbuf, N, l, ri, exact0);
            H = rc_val(mc);
            e = (ij + 1.0) * s;
            float dtx = D.x > 0.0 ? (e.x - P0.x) * invD.x : RC_FAR;
            float dty = D.y > 0.0 ? (e.y - P0.y) * invD.y : RC_FAR;
            dt = max(min(min(dtx, dty), dtz), sP);
            cx = dtx <= dt; cy = dty <= dt; cz = dtz <= dt;
            X = P0 + dt * D;
            if (cx) X.x = e.x;
            if (cy) X.y = e.y;
            if (cz) X.z = D.z < 0.0 ? zr.x : zr.y;
            bool boxhit = D.z >= 0.0 ? P.z <= H : X.z <= H;
            bool fin = l <= lmin;
#if LOD
            fin = fin || rc_lod_final(l, ij, rc_bound(mc, dqf, dqb), Om, zr_m.x, spacing, lod_k);
#endif
            if (boxhit && fin) { cand = true; break; }
            if (!boxhit && cz) return RC_MISS;
            // one step, with selects rather than branches (a SIMD rasterizer runs every branch for every lane):
            // where the box is hit, descend a level (down to where the ray meets the box's top, if later); else
            // move to the exit X and, leaving through an even-level border, ascend
            float sa = D.z < 0.0 ? (H - P0.z) * invDz : -1.0;
            bool adv = boxhit && sa > sP;
            vec3 Pa = P0 + sa * D;
            Pa.xy = min(Pa.xy, e);
            P = adv ? Pa : (boxhit ? P : X);
            sP = adv ? sa : (boxhit ? sP : dt);
            moved = moved || adv || !boxhit;
#if NAIVE
            bool up = false;
#else
            bool up = !boxhit && !under && rc_climbs(ij, cx, cy);
#endif
            l = boxhit ? l - 1 : (up ? min(l + 1, ltop) : l);
        }
        if (!cand) return RC_CAPPED;
        // the ray enters the box of final texel ri at level l between P and X: intersect the cell's surface
        vec3 A = P, B = X;
        if (mx) { A.x = Nf - A.x; B.x = Nf - B.x; }
        if (my) { A.y = Nf - A.y; B.y = Nf - B.y; }
        ivec2 c0 = ri * (1 << l);
        int S = 1 << l;
        vec4 h4 = rc_corners(hmap, c0, S, unit_cells);
        // the exact bound, the planes reconstruction's surface: a level-0 cell's own corners (its step read its
        // parent's bound), else the texel's max-mip height
        H = l == 0 ? max(max(h4.x, h4.y), max(h4.z, h4.w)) : rc_val(mc);
        // a ray under the sheet crosses it upward: the same test with heights and ray z mirrored (z -> -z)
        float sg = under ? -1.0 : 1.0;
        float u = rc_cell_hit(vec3(A.xy, sg * A.z), vec3(B.xy, sg * B.z), vec2(c0), float(S), sg * h4, sg * H);
        if (u >= 0.0) {
            if (u == 0.0 && !moved && no_entry_hit) return RC_MISS;
            vec3 Q = mix(A, B, u);
            if (Q.x > ext.x + 1e-4 || Q.y > ext.y + 1e-4) return RC_MISS;   // first hit lies in the padding
            Q.xy = clamp(Q.xy, elo, ext);
            Q.z = (Q.z + zb) * dqf.y + dqf.x;   // back to metres
            hit = Q; cell = ri; level = l; hc = (h4 + zb) * dqf.y + dqf.x;
            return RC_HIT;
        }
        if (cz) return RC_MISS;
        P = X;
        sP = dt;
        moved = true;
#if !NAIVE
        if (rc_climbs(ij, cx, cy) && !under) l = min(l + 1, ltop);
#endif
    }
}
