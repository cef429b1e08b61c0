// Everything a raster shader needs to know about the tile it draws, one std140 block per tile written once a
// frame for all tiles (raster.tileblock); eye-relative metres, tile-local cells.
layout(std140, binding = 0) uniform TileBlock {
    vec4 t_origin;            // tile sample [0, 0] minus eye (z: terrain origin z minus eye z); w unused
    vec4 t_spacing;           // xy: metres per tile cell east-west and north-south (1, 1 for metre meshes)
    vec4 t_clip_rel;          // tile.clip minus eye: x0, y0, x1, y1
    vec4 t_uv;                // texture coordinate of tile sample [0, 0]; texture step per tile cell
    ivec4 t_shape;            // cells a side, coarsest local level, first node dispatched, pyramid level
    ivec4 t_nb_delta;         // W, E, S, N: neighbour tile level minus this tile's; 9 = no neighbour
    ivec4 t_flags;            // skirt edges (W=1 E=2 S=4 N=8), cull (0/1), level-0 cell (column, row) of sample [0, 0]
    vec4 t_skirt;             // eye-relative z of the skirts' lower edge
    ivec4 t_offsets[4];       // start of each local level's node grid (with apron) in the node buffer
    ivec4 t_starts[4];        // index of each local level's first node among the tile's own nodes
};
#define origin_rel (t_origin.xyz)
#define spacing (t_spacing.xy)
#define clip_rel (t_clip_rel)
#define uv_origin (t_uv.xy)
#define uv_per_cell (t_uv.zw)
#define n_cells (t_shape.x)
#define top (t_shape.y)
#define first_id (t_shape.z)
#define tile_level (t_shape.w)
#define nb_delta (t_nb_delta)
#define skirt_edges (t_flags.x)
#define cull (t_flags.y != 0)
#define tile_cell (t_flags.zw)
#define skirt_bottom (t_skirt.x)
#define offsets(m) (t_offsets[(m) >> 2][(m) & 3])
#define starts(m) (t_starts[(m) >> 2][(m) & 3])
