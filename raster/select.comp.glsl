#version 430
// GPU leaf selection of every tile of a frame's tilelet quadtree (raster.nodes), in two passes (PASS 0 lists,
// PASS 1 emits), each one dispatch over all the frame's items (tile drawings): a work group finds its item and
// its place in the item's work in the work table (raster.frame_items), and its tile's data in the heaps
// (raster.heap) through the item's tile block.
// A node is a leaf when its parent splits and it does not; its edge midpoint is dropped where the same-size
// neighbour's parent does not split (that side is one level coarser), and where neither the leaf nor its
// same-size neighbour is near its own split (lean leaves, below). The leaf's nine post heights are
// fetched and geomorphed, and it is appended as a record (geometry-shader path) or as 9 vertices and 24
// indices (indexed path) for the tile's indirect draw, with skirt segments where asked.
// Buffer layouts and bindings come as defines from Python (raster.selection.select_defines): CONTROL_WORDS cmd[]
// words per item, its indirect commands CMD_POINTS_ and CMD_TEMPLATE_, the item's first leaf in the arena
// (BASE_WORD), its pass-0 work groups finished (DONE_WORD) and in all (GROUPS_WORD), its leaves listed by pass 0
// (FOUND_WORD); WORK_HEADER words of work[] before pass 0's table; LOCAL invocations a work group; SEGMENT_WORDS a
// skirt segment; LEAF_RECORD_WORDS, LEAF_VERTICES and LEAF_INDICES a leaf; frame_count[]'s ARENA_FIELD (arena
// leaves reserved this frame) and OVERFLOW_FIELD (leaves of tiles that did not fit, drawn nothing).
#if !defined(CONTROL_WORDS) || !defined(LEAF_RECORD_WORDS) || !defined(NODES_BINDING) || !defined(ARENA_FIELD)
#error "select.comp.glsl needs the defines of raster.selection.select_defines"
#endif
#extension GL_ARB_shader_ballot : enable
#extension GL_ARB_gpu_shader_int64 : enable
#include "raster/tile_block"
layout(local_size_x = LOCAL) in;
// E, zlo, zhi, inside (0 beyond the grid, else 1 + side codes); one apron
layout(std430, binding = NODES_BINDING) readonly buffer Nodes { vec4 node[]; };
// arena: LEAF_RECORD_WORDS a leaf: j0 i0 m drop, h[9] (LEAN_FULL_RES: and the turns)
layout(std430, binding = RECORDS_BINDING) writeonly buffer Leaves { uint leaf[]; };
// per item CONTROL_WORDS: indirect draws, 5 words each, then the item's arena base, pass-0 groups done, its pass-0
// groups and its leaf count
layout(std430, binding = CONTROL_BINDING) buffer Commands { uint cmd[]; };
// SEGMENT_WORDS a skirt segment, per item from segments_base
layout(std430, binding = SEGMENTS_BINDING) writeonly buffer Skirts { float seg[]; };
// triangles, leaves, culled, segments, arena leaves reserved, overflow
layout(std430, binding = FRAME_BINDING) buffer Frame { uint frame_count[]; };

layout(std430, binding = VERTICES_BINDING) writeonly buffer MeshVerts { vec4 mesh_vertex[]; }; // arena: LEAF_VERTICES a leaf
layout(std430, binding = INDICES_BINDING) writeonly buffer MeshIndex { uint mesh_index[]; };   // arena: LEAF_INDICES a leaf
layout(std430, binding = FOUND_BINDING) buffer Found { uint found[]; };    // per item from found_base: its leaves
// per tile from heights_base: (n+1)^2 samples, row from south, metres from the origin z
layout(std430, binding = HEIGHTS_BINDING) readonly buffer Heights { float height[]; };
// pass 1's dispatch (x, 1, 1), 1 unused, then pass 0's work table (item | group << 16 per work group), then
// pass 1's from table1_start (written by pass 0)
layout(std430, binding = WORK_BINDING) buffer Work { uint work[]; };
uniform float k_tau;            // K / tau: a node splits when E * k_tau > distance to its box
uniform float beta;             // morph-safe error growth (raster.quadtree)
uniform bool stitch;            // drop midpoints toward coarser neighbours (off: cracks, for tests)
uniform bool morph;             // geomorph the posts a split creates (off: they appear at their own height)
uniform bool lean;              // drop the edge midpoints that no finer neighbour and no near split needs
uniform bool write_records;     // leaf records for the geometry-shader path (raster.tilelets)
uniform bool write_mesh;        // vertices and indices for the plain indexed draw (raster.indexed)
uniform vec4 planes[6];         // eye-relative frustum planes, inside where dot >= 0
uniform uint arena_capacity;    // leaves the frame's arena holds (raster.arena)
uniform vec3 eye_terrain;       // eye minus the terrain's origin, metres
uniform vec2 cell_metres;       // the terrain's level-0 spacing (x, y), metres
uniform bool side_errors;       // nodes carry side codes and split on their full fans' errors (raster.quadtree)
uniform uint table1_start;      // work[]: where pass 1's work table starts
// Lean full resolution (LEAN_FULL_RES; raster.tilelets, full_res "lean"): full-resolution leaves drop edge midpoints by their
// side errors as every other leaf does, and a level-0 leaf's SE and NW cells turn from the reference's diagonal
// to the fan's through a post at the cell's centre, morphed from the mean of the one diagonal's ends to the
// other's as the cell's midpoints morph (its turn: the larger of their morph factors from TURN_FROM to 1, where
// the midpoint drops; raster.morph.turn_factor), so that a drop never moves the surface in one frame: 4 triangles
// a turning cell, at most 12 a leaf.

#define CMD0 (tile_item * CONTROL_WORDS)
#define FOUND0 uint(found_base)

int side_of(int m) { return n_cells >> (m + 1); }

// owner tile of node (m, a, b) relative to this one: 0 own, else the edge neighbour's level difference
int owner_delta(int m, int a, int b) {
    int s = side_of(m);
    if (b < 0) return nb_delta.x;
    if (b >= s) return nb_delta.y;
    if (a < 0) return nb_delta.z;
    if (a >= s) return nb_delta.w;
    return 0;
}

vec4 node_at(int m, int a, int b) { return node[offsets(m) + (a + 1) * (side_of(m) + 2) + (b + 1)]; }

// distance (metres) from the eye to node (m, a, b)'s box: its level-0 cells grown by its side, in the terrain's
// frame; every tile that reads this node (its own, a neighbour through its apron) gets the same distance, so
// they agree on splits and morphs
float box_distance(int m, int a, int b, vec4 nd) {
    int S = (2 << m) << tile_level;
    ivec2 c0 = tile_cell + ivec2(b - 1, a - 1) * S;
    vec3 lo = vec3(vec2(c0) * cell_metres, nd.y) - eye_terrain;
    vec3 hi = vec3(vec2(c0 + 3 * S) * cell_metres, nd.z) - eye_terrain;
    return length(max(max(lo, -hi), vec3(0.0)));
}

// 1 split, 0 not split, -1 split by the tile tree (forced), for any node of this tile or its apron;
// E and d (effective error, distance to the box) where the node has data, else d = -1
int split_state(int m, int a, int b, out float E, out float d) {
    E = 0.0; d = -1.0;
    if (m > top) return -1;                      // above the tile's root: the tile tree refined it
    int delta = owner_delta(m, a, b);
    if (delta == 9) return -1;                   // beyond the terrain: nothing to match
    int mb = m - delta;                          // the node's local level in its own tile
    if (mb < 1) return 0;                        // that tile's finest nodes cannot split
    vec4 nd = node_at(m, a, b);
    if (nd.w == 0.0) return -1;
    d = box_distance(m, a, b, nd);
    E = nd.x;
    if (mb >= top) return -1;                    // that tile's root (or above): always split
    return E * k_tau > d ? 1 : 0;
}

// Lean factors of the sides W, E, S, N of a same-pyramid-level node that does not split: side e's is 1 while
// the node's tolerance (d / k_tau) is at least S / beta, falling to 0 as the tolerance falls to S, where S is
// the larger of E and the side's stitched error (decoded from its code against the parent's E, never below the
// measured one: raster.nodes.side_codes); all 0 where it splits or has no data. An edge midpoint between two
// such leaves lies on their edge by the smaller of their two factors, so it is dropped while that is 1 (both
// sides' triangles meet the tolerance by beta) and has reached its own height when either side's triangle
// needs it or either leaf splits (S >= E). Every node whose split makes a leaf has E at least 1 / beta times
// the leaf's and than the side errors of the leaves outside it that face it, so a leaf starts lean and a
// coarser neighbour's leaves see it lean. Without side codes (a tile store's nodes) E bounds both fans and
// every side's S is E. Full-resolution leaves keep every midpoint but toward coarser neighbours (a drop there
// turns their SE and NW cells' diagonals), unless LEAN_FULL_RES, where those cells turn gradually (put_mesh).
vec4 lean_of(int m, int a, int b) {
#ifndef LEAN_FULL_RES
    if (m == 0 && tile_level == 0) return vec4(0.0);    // full resolution: the reference's cells
#endif
    float E, d;
    if (split_state(m, a, b, E, d) != 0) return vec4(0.0);
    vec4 nd = node_at(m, a, b);
    if (nd.w == 0.0) return vec4(0.0);
    vec4 S = vec4(nd.x);
    bvec4 keep = bvec4(false);
    if (side_errors) {                                  // each side's error, coded against the parent's E
        if (m >= top) return vec4(0.0);
        uvec4 code = (uvec4(uint(nd.w) - 1u) >> uvec4(0u, 6u, 12u, 18u)) & 63u;
        keep = equal(code, uvec4(63u));                 // at or above the parent's E: the midpoint stays
        S = node_at(m + 1, a >> 1, b >> 1).x * exp2((vec4(code) - 56.0) / 8.0);
    }
    float dist = box_distance(m, a, b, nd);
    vec4 f;
    for (int e = 0; e < 4; ++e) {
        if (keep[e]) { f[e] = 0.0; continue; }
        if (S[e] <= 0.0) { f[e] = 1.0; continue; }
        float r = dist / (S[e] * k_tau);
        f[e] = !morph ? (r >= 1.0 / beta ? 1.0 : 0.0) : clamp((r - 1.0) / (1.0 / beta - 1.0), 0.0, 1.0);
    }
    return f;
}

bool splits(int m, int a, int b) { float E, d; return split_state(m, a, b, E, d) != 0; }

// morph factor of the posts a split node created (its state, error and distance from split_state): 1 on
// the coarser surface (just split), 0 own height. A tile's root is split by force; its factor still follows
// its error, so a whole tile changing pyramid level morphs as a node inside a tile does
float alpha_of(int st, float E, float d) {
    if (st == 0 || d < 0.0 || !morph) return 0.0;
    if (E <= 0.0) return 1.0;
    return clamp((d / (E * k_tau) - beta) / (1.0 - beta), 0.0, 1.0);
}

#include "raster/select_append"

float H(int i, int j) { return height[heights_base + i * (n_cells + 1) + j]; }

void put_segment(vec2 p, float hp, vec2 q, float hq) {
    uint k = reserve(11, -1, 3);
    uint w = uint(segments_base) + uint(SEGMENT_WORDS) * k;
    seg[w + 0u] = p.x; seg[w + 1u] = p.y; seg[w + 2u] = hp;
    seg[w + 3u] = q.x; seg[w + 4u] = q.y; seg[w + 5u] = hq;
}

// true if node (m, a, b)'s box (its square, the height range of its grown box, the skirts) is wholly
// outside one frustum plane: its drawn surface and skirts are too
bool outside(int m, int a, int b) {
    int s = side_of(m);
    float S = float(2 << m);
    vec4 nd = node[offsets(m) + (a + 1) * (s + 2) + (b + 1)];
    vec3 bmin = origin_rel + vec3(vec2(float(b), float(a)) * S * spacing, min(nd.y, skirt_edges != 0 ? skirt_bottom : nd.y));
    vec3 bmax = origin_rel + vec3(vec2(float(b) + 1.0, float(a) + 1.0) * S * spacing, nd.z);
    for (int p = 0; p < 6; ++p) {
        vec3 n = planes[p].xyz;
        vec3 far_corner = vec3(n.x >= 0.0 ? bmax.x : bmin.x, n.y >= 0.0 ? bmax.y : bmin.y,
                               n.z >= 0.0 ? bmax.z : bmin.z);
        if (dot(n, far_corner) + planes[p].w < 0.0) return true;
    }
    return false;
}

// true if node (m, a, b)'s square lies wholly outside the tile's clip rectangle: nothing of it would be drawn
// (a tile drawn for a missing finer one is clipped to that one's rectangle, hybrid.uploads)
bool outside_clip(int m, int a, int b) {
    vec2 S = float(2 << m) * spacing;
    vec2 lo = origin_rel.xy + vec2(float(b), float(a)) * S, hi = lo + S;
    vec2 tol = 1e-4 * S;
    return any(lessThan(hi + tol, clip_rel.xy)) || any(greaterThan(lo - tol, clip_rel.zw));
}

#if PASS == 1
// posts [row * 3 + col]; counter-clockwise seen from above
const int FAN[24] = int[24](4, 0, 1, 4, 1, 2,  4, 2, 5, 4, 5, 8,  4, 8, 7, 4, 7, 6,  4, 6, 3, 4, 3, 0);
const int SE_CELL[6] = int[6](1, 2, 5, 1, 5, 4);    // replaces fan triangles 1 and 2
const int NW_CELL[6] = int[6](3, 4, 7, 3, 7, 6);    // replaces fan triangles 5 and 6
const int EDGE_BIT[4] = int[4](4, 2, 8, 1);         // fan triangle pairs: S, E, N, W
const int EDGE_END[4] = int[4](2, 8, 6, 0);         // each edge's second corner

// The leaf as 9 vertices (tile-local metres, local level) and 24 indices: the fan around its centre, where
// a dropped edge's two triangles become one and a degenerate one (stitching); in level-0 leaves the
// south-east and north-west cells (fan diagonal NW-SE) are split SW-NE as the reference wherever their two
// outer edges keep their midpoints (the other two cells' fan diagonal is SW-NE already). With LEAN_FULL_RES
// such a cell that is turning (turn.x: SE, turn.y: NW, > 0) is 4 triangles around its centre post (vertices 9
// and 10), two in the fan's slots and two in the leaf's last 12 indices (degenerate where no cell turns).
const int SE_TURN[12] = int[12](1, 2, 9, 2, 5, 9,  5, 4, 9, 4, 1, 9);
const int NW_TURN[12] = int[12](3, 4, 10, 4, 7, 10,  7, 6, 10, 6, 3, 10);
void put_mesh(uint idx, int m, int j0, int i0, int k, int drop, float h[9], vec2 turn) {
    uint vb = idx * LEAF_VERTICES;
    for (int q = 0; q < 9; ++q)
        mesh_vertex[vb + uint(q)] = vec4(vec2(j0 + (q % 3) * k, i0 + (q / 3) * k) * spacing, h[q], float(m));
    bool se_turn = turn.x > 0.0, nw_turn = turn.y > 0.0;
    bool se_ref = m == 0 && (drop & 6) == 0 && !se_turn, nw_ref = m == 0 && (drop & 9) == 0 && !nw_turn;
#ifdef LEAN_FULL_RES
    mesh_vertex[vb + 9u] = vec4(vec2(float(j0) + 1.5 * float(k), float(i0) + 0.5 * float(k)) * spacing,
                                mix(0.5 * (h[1] + h[5]), 0.5 * (h[4] + h[2]), turn.x), float(m));
    mesh_vertex[vb + 10u] = vec4(vec2(float(j0) + 0.5 * float(k), float(i0) + 1.5 * float(k)) * spacing,
                                 mix(0.5 * (h[3] + h[7]), 0.5 * (h[4] + h[6]), turn.y), float(m));
    uint xb = idx * LEAF_INDICES + 24u;
    for (int v = 0; v < 6; ++v) {
        mesh_index[xb + uint(v)] = vb + uint(se_turn ? SE_TURN[v + 6] : 4);
        mesh_index[xb + 6u + uint(v)] = vb + uint(nw_turn ? NW_TURN[v + 6] : 4);
    }
#endif
    uint ib = idx * LEAF_INDICES;
    for (int v = 0; v < 24; ++v) {
        int t = v / 3, e = t / 2;
        int post = FAN[v];
        if (se_turn && (t == 1 || t == 2)) post = SE_TURN[v - 3];
        else if (nw_turn && (t == 5 || t == 6)) post = NW_TURN[v - 15];
        else if (se_ref && (t == 1 || t == 2)) post = SE_CELL[v - 3];
        else if (nw_ref && (t == 5 || t == 6)) post = NW_CELL[v - 15];
        else if ((drop & EDGE_BIT[e]) != 0) {
            if ((t & 1) == 0 && (post & 1) == 1) post = EDGE_END[e];    // (C, a, m) -> (C, a, b)
            else if ((t & 1) == 1) post = 4;                             // (C, m, b) -> degenerate
        }
        mesh_index[ib + uint(v)] = vb + uint(post);
    }
}

// append leaf (m, a) of this tile, whose parent splits and which does not: stitch, morph, cull, store
void emit_leaf(int m, int a, int b) {
    int s = side_of(m);
    int k = 1 << m;
    int i0 = a * 2 * k, j0 = b * 2 * k;
    // edges W, E, S, N: neighbour offsets and drop bits
    const ivec2 nb[4] = ivec2[4](ivec2(0, -1), ivec2(0, 1), ivec2(-1, 0), ivec2(1, 0));
    const int bit[4] = int[4](1, 2, 4, 8);
    float E, d;
    float ap = alpha_of(split_state(m + 1, a >> 1, b >> 1, E, d), E, d);
    int drop = 0;
    float am[4];
    const int opposite[4] = int[4](1, 0, 3, 2);
    vec4 own = lean ? lean_of(m, a, b) : vec4(0.0);
    int skirts = 0;
    if (skirt_edges != 0) {
        if (b == 0) skirts |= skirt_edges & 1;
        if (b == s - 1) skirts |= skirt_edges & 2;
        if (a == 0) skirts |= skirt_edges & 4;
        if (a == s - 1) skirts |= skirt_edges & 8;
    }
    for (int e = 0; e < 4; ++e) {
        int na = a + nb[e].x, nbb = b + nb[e].y;
        float own_lean = own[e];
        am[e] = ap;
        float le = 0.0;
        if ((na >> 1) == (a >> 1) && (nbb >> 1) == (b >> 1)) {          // a sibling: same parent
            if (lean) le = min(own_lean, lean_of(m, na, nbb)[opposite[e]]);
        } else {
            int st = split_state(m + 1, na >> 1, nbb >> 1, E, d);
            if ((skirts & bit[e]) != 0) {                        // a ray-cast tile's exact edge: no stitch, no
                am[e] = ap;                                      // lean drop; the midpoint morphs with the
                continue;                                        // leaf's own parent only (skirts close the gap)
            }
            if (st == 0) { if (stitch) drop |= bit[e]; }
            else {
                am[e] = max(ap, alpha_of(st, E, d));
                if (lean) le = min(own_lean, lean_of(m, na, nbb)[opposite[e]]);
            }
            // on a border with a tile of another pyramid level the two sides cannot see each other's forced
            // (tile root) morphs: the shared posts stay at their own heights on both sides
            int od = owner_delta(m, na, nbb);
            if (od == 9) le = own_lean;                                  // the terrain's edge: no neighbour
            else if (od != 0) { am[e] = 0.0; le = 0.0; }
        }
        am[e] = max(am[e], le);
        if (lean && am[e] >= 1.0) drop |= bit[e];            // on the edge: its two triangles as one
    }
    float h[9];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            h[r * 3 + c] = H(i0 + r * k, j0 + c * k);
    // morph targets: edge midpoints toward the mean of their corners, the centre toward the mean of the
    // diagonal through the parent's centre (SW-NE in the parent's SW and NE quadrants, NW-SE otherwise)
    h[3] = mix(h[3], 0.5 * (h[0] + h[6]), am[0]);
    h[5] = mix(h[5], 0.5 * (h[2] + h[8]), am[1]);
    h[1] = mix(h[1], 0.5 * (h[0] + h[2]), am[2]);
    h[7] = mix(h[7], 0.5 * (h[6] + h[8]), am[3]);
    float diag = ((b & 1) == (a & 1)) ? 0.5 * (h[0] + h[8]) : 0.5 * (h[2] + h[6]);
    h[4] = mix(h[4], diag, ap);
    uint idx = cmd[CMD0 + BASE_WORD] + reserve(0, 5, 1);
    vec2 turn = vec2(0.0);          // LEAN_FULL_RES: the SE and NW cells' turns (0: the reference's diagonal)
#ifdef LEAN_FULL_RES
    if (m == 0) turn = clamp((vec2((drop & 6) == 0 ? max(am[1], am[2]) : 0.0, (drop & 9) == 0 ? max(am[0], am[3]) : 0.0)
                              - TURN_FROM) / (1.0 - TURN_FROM), 0.0, 1.0);
#endif
    if (write_mesh) put_mesh(idx, m, j0, i0, k, drop, h, turn);
    add_total(0, uint(8 - bitCount(drop) + 2 * int(turn.x > 0.0) + 2 * int(turn.y > 0.0)));
    if (write_records) {
        uint w = idx * LEAF_RECORD_WORDS;
        leaf[w + 0] = uint(j0); leaf[w + 1] = uint(i0); leaf[w + 2] = uint(m); leaf[w + 3] = uint(drop);
        for (int q = 0; q < 9; ++q) leaf[w + 4u + uint(q)] = floatBitsToUint(h[q]);
#ifdef LEAN_FULL_RES
        leaf[w + 13u] = floatBitsToUint(turn.x); leaf[w + 14u] = floatBitsToUint(turn.y);
#endif
    }
    // skirts below the tile edges that face ray-cast tiles, one segment per drawn edge piece
    const ivec4 EDGE_POSTS[4] = ivec4[4](ivec4(0, 3, 6, 1), ivec4(2, 5, 8, 2), ivec4(0, 1, 2, 4), ivec4(6, 7, 8, 8));
    for (int e = 0; e < 4; ++e) {
        ivec4 ep = EDGE_POSTS[e];
        if ((skirts & ep.w) == 0) continue;
        vec2 pa = vec2(j0 + (ep.x % 3) * k, i0 + (ep.x / 3) * k);
        vec2 pm = vec2(j0 + (ep.y % 3) * k, i0 + (ep.y / 3) * k);
        vec2 pb = vec2(j0 + (ep.z % 3) * k, i0 + (ep.z / 3) * k);
        if ((drop & ep.w) != 0) put_segment(pa, h[ep.x], pb, h[ep.z]);
        else { put_segment(pa, h[ep.x], pm, h[ep.y]); put_segment(pm, h[ep.y], pb, h[ep.z]); }
    }
}

// Two programs (PASS 0 and 1), so that the costly part runs without idle lanes: pass 0 has one invocation
// per node and lists the leaves (parent splits, node does not) with their count and the work groups of
// pass 1; pass 1, dispatched from that count, has one invocation per leaf and emits it.
#endif

#if PASS == 0
// nodes of local level >= 1 (level 0 only in a 2-cell tile): a split level-1 node lists its four
// children itself, which keeps three quarters of the nodes out of this pass
void list_node(uint gid) {
    int id = first_id + int(gid);
    if (id >= starts(top + 1)) return;
    int m = min(1, top);
    // the node's level: a for with a fixed cap (12 levels), as NVIDIA's GLSL compiler (H200, driver of 2026-12)
    // lost every node of level >= 2 with the equivalent while loop on a uniform-block array
    for (int k = 2; k <= 12; ++k) { if (k > top || id < starts(k)) break; m = k; }
    int s = side_of(m);
    int local = id - starts(m);
    int a = local / s, b = local % s;
    if (m == 1 && splits(1, a, b)) {
        for (int c = 0; c < 4; ++c) {
            int ca = 2 * a + (c >> 1), cb = 2 * b + (c & 1);
            if (outside_clip(0, ca, cb)) continue;
            if (cull && outside(0, ca, cb)) { add_total(2, 1u); continue; }
            uint i = reserve_found();
            found[FOUND0 + i] = uint(ca << 4) | (uint(cb) << 18);
        }
        return;
    }
    if (!splits(m + 1, a >> 1, b >> 1) || splits(m, a, b)) return;
    if (outside_clip(m, a, b)) return;
    if (cull && outside(m, a, b)) { add_total(2, 1u); return; }
    uint i = reserve_found();
    found[FOUND0 + i] = uint(m) | (uint(a) << 4) | (uint(b) << 18);
}

shared bool s_last;             // this work group is the item's last to finish pass 0
shared uint s_groups, s_first;  // the item's pass-1 work groups and where they start in pass 1's table

// Run by the last pass-0 work group of the item, when every leaf is listed: the item's leaves get their
// place in the frame's arena, the draw commands start there and its pass-1 work groups are reserved; an item
// that does not fit emits nothing.
void reserve_arena() {
    uint count = atomicAdd(cmd[CMD0 + FOUND_WORD], 0u);
    uint base = atomicAdd(frame_count[ARENA_FIELD], count);
    if (base + count > arena_capacity) {
        atomicAdd(frame_count[OVERFLOW_FIELD], count);
        cmd[CMD0 + FOUND_WORD] = 0u;
        count = 0u;
        base = 0u;
    }
    cmd[CMD0 + BASE_WORD] = base;
    cmd[CMD0 + 5 * CMD_POINTS_ + 2] = base;           // DrawArraysIndirect: first
    cmd[CMD0 + 5 * CMD_TEMPLATE_ + 2] = LEAF_INDICES * base;   // DrawElementsIndirect: first index
    s_groups = (count + uint(LOCAL) - 1u) / uint(LOCAL);
    s_first = atomicAdd(work[0], s_groups);
}
#endif

void main() {
#if PASS == 0
    uint entry = work[WORK_HEADER + gl_WorkGroupID.x];
#else
    uint entry = work[table1_start + gl_WorkGroupID.x];
#endif
    use_tile_item(int(entry & 65535u));
    uint gid = (entry >> 16) * uint(LOCAL) + gl_LocalInvocationID.x;
#if PASS == 0
    list_node(gid);
    memoryBarrierBuffer();
    barrier();
    if (gl_LocalInvocationIndex == 0u) {
        s_last = atomicAdd(cmd[CMD0 + DONE_WORD], 1u) == cmd[CMD0 + GROUPS_WORD] - 1u;
        if (s_last) reserve_arena();
    }
    barrier();
    // the item's pass-1 work groups into pass 1's table, shared by the work group (at most 2^16 a tile)
    if (s_last)
        for (uint j = gl_LocalInvocationIndex; j < min(s_groups, 65536u); j += uint(LOCAL))
            work[table1_start + s_first + j] = uint(tile_item) | (j << 16);
#else
    if (gid >= cmd[CMD0 + FOUND_WORD]) return;
    uint w = found[FOUND0 + gid];
    emit_leaf(int(w & 15u), int((w >> 4) & 16383u), int(w >> 18));
#endif
}
