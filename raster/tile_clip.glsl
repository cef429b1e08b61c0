// Clipping to the tile's real terrain (tile.clip), for the stages that emit vertices (raster.tileblock).
out float gl_ClipDistance[4];

// Clip distances of an eye-relative point against the tile's clip rectangle; ``open_axis`` 0 (x) or 1 (y)
// leaves that axis unclipped (a skirt lies on that side of the rectangle itself), -1 clips both.
void clip_to_tile(vec3 p, int open_axis) {
    gl_ClipDistance[0] = open_axis == 0 ? 1.0 : p.x - clip_rel.x;
    gl_ClipDistance[1] = open_axis == 1 ? 1.0 : p.y - clip_rel.y;
    gl_ClipDistance[2] = open_axis == 0 ? 1.0 : clip_rel.z - p.x;
    gl_ClipDistance[3] = open_axis == 1 ? 1.0 : clip_rel.w - p.y;
}
