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

// Anisotropic filtering from explicit derivatives (uv per pixel along x and y): up to 16 textureGrad taps
// along the footprint's major axis, each filtered isotropically at the minor axis' size. Every method filters
// the terrain texture with it (the ray caster from its analytic footprint, the rasterized ones from dFdx/dFdy),
// so a point looks the same whichever draws it, and the texture object has anisotropy 1: the driver's own
// anisotropic path may ignore textureGrad's derivatives and, on Mesa llvmpipe, costs about 15x as much.
vec3 aniso_texture(sampler2D tex, vec2 uv, vec2 gx, vec2 gy) {
    vec2 ts = vec2(textureSize(tex, 0));
    float lx = length(gx * ts), ly = length(gy * ts);
    vec2 major = lx >= ly ? gx : gy;
    float lmaj = max(lx, ly), lmin = min(lx, ly);
    int taps = int(clamp(ceil(lmaj / max(lmin, 1e-8)), 1.0, 16.0));
    float lm = max(lmin, lmaj / 16.0);
    vec2 g = vec2(lm, 0.0) / ts;
    vec3 acc = vec3(0.0);
    for (int k = 0; k < taps; k++) {
        vec2 off = major * ((float(k) + 0.5) / float(taps) - 0.5);
        acc += textureGrad(tex, uv + off, g, g.yx).rgb;
    }
    return acc / float(taps);
}
