"""Cameras: the float64 view with its reversed-Z projection, and flights (presets, JSON/CSV paths)."""
