#version 430
// The tile's clipped bounding box, eye-relative; only its back faces are drawn (front faces culled).
in vec3 corner;                // unit cube corner in {0, 1}^3
#include "raycast/tile_block"
uniform mat4 view_proj_rel;    // (world - eye) -> clip, reversed Z
void main() {
    gl_Position = view_proj_rel * vec4(mix(box_lo, box_hi, corner), 1.0);
}
