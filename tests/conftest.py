"""Shared fixtures: one GL context for the whole test session, small terrains and viewports.

Every test that needs the GL context (through the ``ctx`` fixture, directly or through another fixture)
is marked ``gl``: it is skipped where no headless EGL context can be made, and fails when it leaves a GL
error behind. Tests without the marker run without any GL context.
"""

import os
import tempfile

import pytest
from gl_errors import gl_errors

from hybrid.terrain.datasets import get_dataset, puget

SMALL = (320, 180)

# no test, fixture or run of any scope reads or writes the user's costs file (a run saves what its hybrid
# learned there): session-scoped work sees an empty one of this process's, modules and tests their own below
os.environ["TERRABENCH_COSTS"] = os.path.join(tempfile.mkdtemp(prefix="terrabench-costs-"), "costs.json")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if "ctx" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.gl)
    # modules with slow tests first (whole, so their module fixtures are made once): spread over the workers
    # (pytest-xdist), the slow tests do not finish the run one after another
    slow = {item.module.__name__ for item in items if item.get_closest_marker("slow") is not None}
    items.sort(key=lambda item: item.module.__name__ not in slow)


@pytest.fixture(scope="session")
def ctx():
    """The one headless GL context of the test session (reversed-Z clip control set); skip without one."""
    from hybrid.errors import GLContextError
    from hybrid.gl.context import shared_context

    try:
        return shared_context()
    except GLContextError as exc:
        pytest.skip(f"no EGL context: {exc}")


@pytest.fixture(autouse=True, scope="module")
def module_costs_file(tmp_path_factory):
    """Each module's fixtures (runs made once for a module) start from an empty costs file of the module's own,
    so a run another module made and saved its learned model from never changes their starting model."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TERRABENCH_COSTS", str(tmp_path_factory.mktemp("module-costs") / "costs.json"))
        yield


@pytest.fixture(autouse=True)
def private_costs_file(tmp_path_factory, monkeypatch):
    """No test reads or writes the user's costs file: each sees an empty one of its own (a run saves what its
    hybrid learned there), so no test's learned model reaches another."""
    monkeypatch.setenv("TERRABENCH_COSTS", str(tmp_path_factory.mktemp("costs") / "costs.json"))


@pytest.fixture(autouse=True)
def gl_error_check(request):
    """For ``gl`` tests: no GL error pending before the test (else fixture setup or an earlier teardown
    raised it, and this says so), and none raised by the test itself."""
    if request.node.get_closest_marker("gl") is None:
        yield
        return
    ctx = request.getfixturevalue("ctx")
    stale = gl_errors(ctx)
    if stale:
        pytest.fail(
            f"GL error(s) {stale} pending before {request.node.nodeid}: raised by fixture setup or "
            f"by an earlier test's teardown",
            pytrace=False,
        )
    yield
    raised = gl_errors(ctx)
    if raised:
        pytest.fail(f"{request.node.nodeid} left GL error(s) {raised} (glGetError after the test)", pytrace=False)


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
