#version 430
// The geometry-shader path: one point per selected leaf (raster/select.comp.glsl), passed on with its
// nine geomorphed post heights; the geometry shader expands it into the tilelet's fan.
layout(location = 0) in ivec4 a_node;     // (j0, i0) south-west post in tile cells, local level m, dropped edges
layout(location = 1) in vec4 a_h0;        // post heights 0..3 ([row * 3 + col], row from south), metres
layout(location = 2) in vec4 a_h1;        // post heights 4..7
layout(location = 3) in float a_h8;       // post height 8
#ifdef LEAN_FULL_RES
layout(location = 4) in vec2 a_turn;      // the SE and NW cells' turns (raster/select.comp.glsl)
#endif
out Tilelet {
    flat ivec4 node;
    flat int culled;
    float h[9];
#ifdef LEAN_FULL_RES
    vec2 turn;
#endif
} vs_out;

void main() {
    vs_out.node = a_node;
    vs_out.culled = 0;
    vs_out.h = float[9](a_h0.x, a_h0.y, a_h0.z, a_h0.w, a_h1.x, a_h1.y, a_h1.z, a_h1.w, a_h8);
#ifdef LEAN_FULL_RES
    vs_out.turn = a_turn;
#endif
    gl_Position = vec4(0.0, 0.0, 0.0, 1.0);
}
