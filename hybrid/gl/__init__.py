"""The GL layer: headless EGL context (reversed Z, 32-bit float depth), frame targets, timing, GLSL programs."""
