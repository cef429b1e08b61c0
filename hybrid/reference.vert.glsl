#version 430
// Full-resolution reference surface: one vertex per height sample, position from gl_VertexID.
uniform sampler2D heights;     // R32F, (cols x rows), row 0 = south
uniform ivec2 grid;            // (cols, rows)
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
    vec3 p = origin_rel + vec3(vec2(j, i) * spacing, h);
    v_rel = p;
    v_uv = vec2(j, i) / vec2(grid - 1);
    v_h = h;
    gl_Position = view_proj_rel * vec4(p, 1.0);
}
