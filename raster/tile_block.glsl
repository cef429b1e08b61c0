// Everything a raster shader needs to know about the tile it draws, one std140 block per tile written once a
// frame for all tiles (raster.tileblock); eye-relative metres, tile-local cells. A draw binds one tile's block
// as the uniform block TileBlock; the selection (a compute shader over every tile of the frame, defining
// TILE_BLOCKS_STORAGE) reads them all as a storage buffer and picks its tile's with ``tile_item``; a multi-draw's
// vertex stage (TILE_BLOCK_ATTRIBUTES) gets its draw's block's first fields as instanced attributes.
// The bindings come as defines (raster.tileblock.BLOCK_DEFINES).
#if !defined(TILE_BLOCK_BINDING) || !defined(TILE_BLOCKS_BINDING)
#error "programs including raster/tile_block need raster.tileblock.BLOCK_DEFINES"
#endif
struct TileData {
    vec4 t_origin;            // tile sample [0, 0] minus eye (z: terrain origin z minus eye z); w unused
    vec4 t_spacing;           // xy: metres per tile cell east-west and north-south (1, 1 for metre meshes)
    vec4 t_clip_rel;          // tile.clip minus eye: x0, y0, x1, y1
    vec4 t_uv;                // texture coordinate of tile sample [0, 0]; texture step per tile cell
    ivec4 t_shape;            // cells a side, coarsest local level, first node dispatched, pyramid level
    ivec4 t_nb_delta;         // W, E, S, N: neighbour tile level minus this tile's; 9 = no neighbour
    ivec4 t_flags;            // skirt edges (W=1 E=2 S=4 N=8), cull (0/1), level-0 cell (column, row) of sample [0, 0]
    vec4 t_skirt;             // eye-relative z of the skirts' lower edge
    ivec4 t_offsets[4];       // start of each local level's node grid (with apron) in the node heap (vec4s)
    ivec4 t_starts[4];        // index of each local level's first node among the tile's own nodes (13 entries
                              // at most); the last three: where the tile's heights (floats), its item's leaf
                              // list and its skirt segments (words) start in their buffers
};
#ifdef TILE_BLOCKS_STORAGE
layout(std430, binding = TILE_BLOCKS_BINDING) readonly buffer TileBlocks { TileData tile_blocks[]; };
int tile_item = 0;            // the frame item (tile drawing) this invocation selects for
TileData TB;                  // its block, read once (use_tile_item)

void use_tile_item(int item) { tile_item = item; TB = tile_blocks[item]; }
#elif defined(TILE_BLOCK_ATTRIBUTES)
TileData TB;                  // its first fields set from instanced attributes (a multi-draw: raster.indexed)
#else
layout(std140, binding = TILE_BLOCK_BINDING) uniform TileBlock { TileData TB; };
#endif
#define origin_rel (TB.t_origin.xyz)
#define spacing (TB.t_spacing.xy)
#define clip_rel (TB.t_clip_rel)
#define uv_origin (TB.t_uv.xy)
#define uv_per_cell (TB.t_uv.zw)
#define n_cells (TB.t_shape.x)
#define top (TB.t_shape.y)
#define first_id (TB.t_shape.z)
#define tile_level (TB.t_shape.w)
#define nb_delta (TB.t_nb_delta)
#define skirt_edges (TB.t_flags.x)
#define cull (TB.t_flags.y != 0)
#define tile_cell (TB.t_flags.zw)
#define skirt_bottom (TB.t_skirt.x)
#define offsets(m) (TB.t_offsets[(m) >> 2][(m) & 3])
#define starts(m) (TB.t_starts[(m) >> 2][(m) & 3])
#define heights_base (TB.t_starts[3].y)
#define found_base (TB.t_starts[3].z)
#define segments_base (TB.t_starts[3].w)
