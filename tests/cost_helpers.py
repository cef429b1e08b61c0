"""A known cost model the cost-model tests draw synthetic frames 'by' and try to recover, and their tiles."""

from hybrid.cost.model import CostModel

TRUE_COEFFICIENTS = {
    "raster": {"const": 0.3, "triangles": 5e-5, "visible_triangles": 1.5e-4, "pixels": 1e-5, "surface_pixels": 2e-5},
    "raycast": {"const": 0.5, "pixels": 2e-5, "surface_pixels": 1e-5, "pixel_steps": 1e-5},
    "raster_gs": {"const": 0.2, "triangles": 2e-4, "visible_triangles": 3e-4, "pixels": 1e-5, "surface_pixels": 2.5e-5},
}


def true_model(**fields) -> CostModel:
    """The known model (a fresh copy of its coefficients), with any other fields given."""
    return CostModel("test", {s: dict(c) for s, c in TRUE_COEFFICIENTS.items()}, **fields)


def columns(rng, n):
    """Feature columns of n synthetic tiles."""
    return {
        "pixels": rng.uniform(500, 40000, n),
        "triangles": rng.uniform(0, 100000, n),
        "slab_cells": rng.uniform(0, 300, n),
        "level": rng.integers(0, 3, n).astype(float),
        "distance": rng.uniform(1e3, 1e5, n),
        "visible": rng.uniform(0.1, 1.0, n),
        "surface_pixels": rng.uniform(0, 30000, n),
    }
