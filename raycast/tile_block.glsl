// One ray-cast tile's parameters, a block of the frame's uniform buffer (std140; raycast.caster.TILE_BLOCK
// writes it with the same offsets). The box, vertex and pre-pass shaders read the same block.
layout(std140, binding = TILE_PARAMS_BINDING) uniform TileParams {
    vec2 dq;               // (offset, step) metres: height = offset + step * (code + dq_base), float32
    vec3 box_lo;           // box min corner minus eye, metres
    int dq_base;
    vec3 box_hi;           // box max corner minus eye, metres
    int n_cells;           // N
    vec3 eye_tex;          // eye in tile texel space
    int n_levels;          // log2 N
    vec3 origin_rel;       // tile origin (sample [0,0] at terrain origin z) minus eye, metres
    int tile_level;        // pyramid level of the tile
    vec2 ext_lo;           // clip rectangle's lower corner in texels from the tile's origin (0 but in a fallback)
    vec2 ext;              // clip rectangle's upper corner in texels from the tile's origin
    vec2 zr;               // tile z range, metres relative to terrain origin z
    vec2 spacing;          // metres per tile texel east-west (x) and north-south (y)
    vec2 uv_off;           // texture coordinate of the tile origin
    vec2 uv_scale;         // texture coordinate per tile texel
    vec2 g_tile_off;       // tile origin in level-0 terrain texels (shadow rays)
    float lod_k;           // max(spacing.x, spacing.y) * K / tau (metres), for LOD
    int max_steps;
    int outer;             // tile box sides on the terrain's outer boundary (W 1, E 2, S 4, N 8)
    int tile_index;        // index into the statistics array
    uint tile_id;          // pre-pass ID
};
