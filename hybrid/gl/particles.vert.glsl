#version 430
// A particle as a point sprite, its position read from the simulation's buffer by gl_VertexID.
layout(std430, binding = 0) readonly buffer Positions { vec4 pos[]; };   // metres relative to the terrain origin
uniform vec3 origin_rel;       // terrain origin minus eye, metres
uniform mat4 view_proj_rel;    // (world - eye) -> clip, reversed Z
uniform float point_px;        // sprite diameter in pixels
void main() {
    gl_Position = view_proj_rel * vec4(origin_rel + pos[gl_VertexID].xyz, 1.0);
    gl_PointSize = point_px;
}
