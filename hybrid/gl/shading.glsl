// Shared colour conventions (hybrid/shading.glsl). Every method shades a surface point the same way:
//   texture mode: the terrain texture at uv = (x - x0, y - y0) / extent (cell-centred texels),
//   shaded mode:  height_ramp(h) * (AMBIENT + (1 - AMBIENT) * max(dot(n, LIGHT_DIR), 0)),
//   height mode:  height_ramp(h).
// h is the height above the terrain's origin z in metres; hrange = (min, max) of the terrain.
const vec3 LIGHT_DIR = vec3(-0.4851, 0.4851, 0.7276);   // unit vector toward the light
const float AMBIENT = 0.3;

vec3 height_ramp(float h, vec2 hrange) {
    float span = hrange.y - hrange.x;
    float t = span > 0.0 ? clamp((h - hrange.x) / span, 0.0, 1.0) : 0.5;
    vec3 c0 = vec3(0.16, 0.36, 0.22), c1 = vec3(0.55, 0.60, 0.35), c2 = vec3(0.55, 0.45, 0.35), c3 = vec3(0.95);
    if (t < 0.35) return mix(c0, c1, t / 0.35);
    if (t < 0.70) return mix(c1, c2, (t - 0.35) / 0.35);
    return mix(c2, c3, (t - 0.70) / 0.30);
}

vec3 lambert(vec3 base, vec3 n) {
    return base * (AMBIENT + (1.0 - AMBIENT) * max(dot(normalize(n), LIGHT_DIR), 0.0));
}
