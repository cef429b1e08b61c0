#version 430
// A round sprite, lit from the upper left so it reads as a ball; depth is the point's own (depth-tested against the
// terrain already drawn in the target).
uniform vec3 colour;           // the balls' colour, linear 0..1
out vec4 frag;
void main() {
    vec2 q = gl_PointCoord * 2.0 - 1.0;
    float r2 = dot(q, q);
    if (r2 > 1.0) discard;
    float lit = 0.55 + 0.45 * clamp(dot(vec3(q.x, -q.y, sqrt(1.0 - r2)), normalize(vec3(-0.5, 0.5, 1.0))), 0.0, 1.0);
    frag = vec4(colour * lit, 1.0);
}
