#version 430
// Full-resolution reference surface, one block of the grid: one vertex per height sample, position from gl_VertexID.
uniform sampler2D heights;     // R32F, the block's samples (cols x rows), row 0 = south
uniform ivec2 grid;            // the block's (cols, rows)
uniform ivec2 first;           // the block's first sample (column, row) in the whole grid
uniform ivec2 full;            // the whole grid's (cols, rows)
uniform vec3 origin_rel;       // terrain origin minus eye, metres
uniform vec2 spacing;          // metres between columns (x, east-west) and rows (y, north-south)
uniform mat4 view_proj_rel;    // (world - eye) -> clip, reversed Z
out vec3 v_rel;
out vec2 v_uv;
out float v_h;
void main() {
    int i = gl_VertexID / grid.x;
    int j = gl_VertexID - i * grid.x;
    float h = texelFetch(heights, ivec2(j, i), 0).r;
    vec2 ij = vec2(j + first.x, i + first.y);
    vec3 p = origin_rel + vec3(ij * spacing, h);
    v_rel = p;
    v_uv = ij / vec2(full - 1);
    v_h = h;
    gl_Position = view_proj_rel * vec4(p, 1.0);
}
