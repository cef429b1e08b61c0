// Whether a pixel's ray starts under the terrain sheet (numpy twin and conventions: hybrid/terrain/edges.py).
// Terrain grid space: x, y in level-0 texels of the whole terrain, z metres relative to its origin z; the
// footprint is [0, grid_cells.x] x [0, grid_cells.y]. Uniforms set by hybrid.gl.edges.TerrainEdges.
uniform sampler2D edges;       // R32F (w, 4k): heights along the S, N, W, E edges, metres relative to the origin
                               // z, each side's L samples wrapped onto k rows of w texels (side s from row s k)
uniform int edge_len;          // L: samples along each edge profile
uniform vec2 grid_cells;       // footprint in level-0 texels: (cols - 1, rows - 1)
uniform vec3 grid_eye;         // eye in terrain grid space
uniform vec2 grid_per_m;       // level-0 texels per metre along x and y
uniform bool eye_under;        // the eye lies over the footprint, below the ground

// Height of the outer edge `side` (0 S, 1 N, 2 W, 3 E) at texel position p along it, linear between samples.
float edge_sample(int side, int i) {
    ivec2 size = textureSize(edges, 0);
    return texelFetch(edges, ivec2(i % size.x, side * (size.y / 4) + i / size.x), 0).r;
}

float edge_height(int side, float p) {
    int k = clamp(int(floor(p)), 0, edge_len - 2);
    return mix(edge_sample(side, k), edge_sample(side, k + 1), p - float(k));
}

// True if the ray from the eye along world direction d (metres) starts under the terrain sheet: from over
// the footprint, when the eye does; from outside, when it enters the footprint below the outer edge.
bool ray_starts_under(vec3 d) {
    vec3 O = grid_eye, D = vec3(d.xy * grid_per_m, d.z);
    if (all(greaterThanEqual(O.xy, vec2(0.0))) && all(lessThanEqual(O.xy, grid_cells))) return eye_under;
    float tn = -1e30, tf = 1e30;
    bool xside = false;
    for (int a = 0; a < 2; a++) {
        if (D[a] != 0.0) {
            float ta = -O[a] / D[a], tb = (grid_cells[a] - O[a]) / D[a];
            if (min(ta, tb) > tn) { tn = min(ta, tb); xside = a == 0; }
            tf = min(tf, max(ta, tb));
        } else if (O[a] < 0.0 || O[a] > grid_cells[a]) {
            return false;
        }
    }
    if (tn > tf || tf < 0.0) return false;
    vec3 P = O + tn * D;
    float h = xside ? edge_height(D.x > 0.0 ? 2 : 3, clamp(P.y, 0.0, grid_cells.y))
                    : edge_height(D.y > 0.0 ? 0 : 1, clamp(P.x, 0.0, grid_cells.x));
    return P.z < h;
}
