"""Shared fixtures: one GL context for the whole test session, small terrains and viewports."""
import pytest

from hybrid.terrain.datasets import get_dataset, puget

SMALL = (320, 180)


@pytest.fixture(scope="session")
def ctx():
    """The one headless GL context of the test session (reversed-Z clip control set)."""
    from hybrid.gl.context import shared_context
    return shared_context()


@pytest.fixture(scope="session")
def puget257():
    """A 257² full-resolution window of Puget Sound around Mount Rainier, with texture."""
    return puget(size=257)


@pytest.fixture(scope="session")
def puget_full():
    """The whole bundled Puget Sound model."""
    return puget()


@pytest.fixture(scope="session")
def synthetic():
    """Factory for seeded 257² synthetic terrains by name."""
    cache = {}

    def make(name, size=257, seed=0):
        if (name, size, seed) not in cache:
            cache[(name, size, seed)] = get_dataset(name, size=size, seed=seed)
        return cache[(name, size, seed)]
    return make
