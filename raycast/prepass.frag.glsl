#version 430
// Tile-ID pre-pass (Dick et al. 3.4): depth-tested against the frame, depth writes off, writes the tile's ID
// where no earlier (nearer) tile has found a hit yet.
#include "raycast/tile_block"
out uint id;
void main() {
    id = tile_id;
}
