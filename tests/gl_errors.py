"""Pending GL errors of a context, for the check the test session runs around every ``gl`` test."""


def gl_errors(ctx, limit: int = 16) -> list[str]:
    """Every pending GL error flag, oldest first (moderngl's Context.error reads and clears one at a time)."""
    out = []
    while len(out) < limit:
        e = ctx.error
        if e == "GL_NO_ERROR":
            break
        out.append(e)
    return out
