"""The strategy and policy registry: every list of names reads it, and a registration shows up everywhere."""

from typing import get_args

import pytest

from experiments.cli import build_parser
from experiments.spec import parse_spec
from hybrid import contract, strategies
from hybrid.errors import TerrabenchError
from hybrid.strategies import PolicyEntry, StrategyEntry, register_policy, register_strategy, unregister
from raycast import RaycastStrategy


class ToyCaster(RaycastStrategy):
    """A ray caster under another name, with one more surface reconstruction."""


@pytest.fixture
def toys():
    register_strategy(StrategyEntry("toycast", "raycast", ToyCaster, "a toy", choices={"reconstruction": ("toy",)}))
    register_policy(
        PolicyEntry("toymix", "a toy mixed policy", rule=lambda cols, pred, t: ["raycast"] * len(cols["pixels"]))
    )
    yield
    unregister("toycast")
    unregister("toymix")


def _option(command: str, dest: str):
    """One option of a subcommand, from a freshly built parser."""
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices[command]
    return next(a for a in sub._actions if a.dest == dest)


def test_typing_literals_match_the_registry():
    assert get_args(contract.StrategyName) == strategies.pure_policies()
    assert get_args(contract.Policy) == strategies.policies()
    assert get_args(contract.Method) == strategies.methods()
    assert {e.kind for e in strategies.STRATEGIES.values()} <= set(get_args(contract.Kind))
    assert strategies.option_choices("full_res") == contract.FULL_RES


def test_registered_toys_appear_in_cli_choices(toys):
    assert {"toycast", "toymix"} <= set(_option("render", "method").choices)
    assert "toy" in _option("render", "reconstruction").help


def test_registered_toys_pass_the_spec_checks(toys):
    spec = parse_spec('policies = ["toycast", "toymix", "raster"]\nreconstructions = ["triangles", "toy"]')
    configs = spec.configs()
    recs = {(c.policy, c.reconstruction) for c in configs}
    assert {("toycast", "toy"), ("toymix", "toy"), ("raster", "triangles")} <= recs
    assert ("raster", "toy") not in recs  # raster casts no rays: one reconstruction only
    assert "toymix" in strategies.mixed_policies() and "toycast" in strategies.pure_policies()


def test_unregistered_names_are_refused():
    assert "toycast" not in _option("render", "method").choices
    with pytest.raises(TerrabenchError, match="unknown policy"):
        parse_spec('policies = ["toycast"]')
    with pytest.raises(TerrabenchError, match="unknown reconstruction"):
        parse_spec('reconstructions = ["toy"]')


def test_a_name_registers_once():
    with pytest.raises(TerrabenchError, match="already registered"):
        register_policy(PolicyEntry("raster", "taken"))
    with pytest.raises(TerrabenchError, match="already registered"):
        register_strategy(StrategyEntry("reference", "raster", ToyCaster, "taken"))


def test_the_planner_follows_a_registered_rule(toys):
    import numpy as np

    from hybrid.cost.planner import choices

    cols = {"pixels": np.ones(3), "triangles": np.ones(3)}
    assert choices("toymix", cols, {}) == ["raycast"] * 3
    assert choices("toycast", cols, {}) == ["toycast"] * 3


def test_the_worked_example_in_the_registry_docstring():
    import numpy as np

    from hybrid.cost.planner import choices
    from hybrid.strategies import heuristic_rule

    def twice(columns, predicted, threshold):
        return heuristic_rule(columns, predicted, 2.0 * threshold)

    register_policy(PolicyEntry("heuristic2", "ray cast where triangles outnumber pixels twice", rule=twice))
    try:
        assert "heuristic2" in _option("render", "method").choices
        cols = {"pixels": np.array([10.0, 10.0]), "triangles": np.array([15.0, 25.0])}
        assert choices("heuristic2", cols, {}) == ["raster", "raycast"]
        assert choices("heuristic", cols, {}) == ["raycast", "raycast"]
        assert parse_spec('policies = ["heuristic2"]').policies == ["heuristic2"]
    finally:
        unregister("heuristic2")
