#version 430
in vec3 v_rel;
in vec2 v_uv;
in float v_h;
uniform int mode;              // 0 texture, 1 shaded, 2 height
uniform sampler2D tex;
uniform vec2 hrange;
out vec4 frag;
#include "shading"
void main() {
    vec3 n = cross(dFdx(v_rel), dFdy(v_rel));
    if (n.z < 0.0) n = -n;
    vec3 c;
    vec2 gx = dFdx(v_uv), gy = dFdy(v_uv);        // in uniform control flow, before the branch
    if (mode == 0) c = aniso_texture(tex, v_uv, gx, gy);
    else if (mode == 1) c = lambert(height_ramp(v_h, hrange), n);
    else c = height_ramp(v_h, hrange);
    frag = vec4(c, 1.0);
}
