"""The tile pyramid (tiles, AABBs, geometric errors) and the per-view tile tree (selection by screen-space error)."""
