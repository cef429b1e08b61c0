"""Ray-cast strategy: per-tile GPU ray casting over a maximum mipmap (Dick et al.)."""
