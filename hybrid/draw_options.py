"""Draw options per strategy: keyword options routed to the strategies that take them, over typed defaults."""

from __future__ import annotations

from collections.abc import Mapping

from hybrid.contract import DrawOptions
from hybrid.errors import TerrabenchError
from hybrid.strategies import STRATEGIES


def route_options(strategies: dict, options: dict) -> dict[str, dict]:
    """Draw options split per strategy by the names its options dataclass has; a name none knows is an error."""
    known = set().union(*(e.option_names for e in STRATEGIES.values()))
    bad = sorted(set(options) - known)
    if bad:
        raise TerrabenchError(f"unknown draw option(s) {', '.join(bad)}; known: {', '.join(sorted(known))}")
    return {n: {k: v for k, v in options.items() if k in STRATEGIES[n].option_names} for n in strategies}


def resolve_options(strategies: dict, given: Mapping[str, DrawOptions] | None, options: dict) -> dict:
    """Each strategy's draw options (its ``options_type``): those ``given`` by strategy name, with the keyword
    ``options`` each takes applied over them; refuses a name or a type that does not fit."""
    given = dict(given or {})
    bad = sorted(set(given) - set(strategies))
    if bad:
        raise TerrabenchError(f"options for strategies this renderer does not draw: {', '.join(bad)}")
    out = {}
    for n, routed in route_options(strategies, options).items():
        kind = STRATEGIES[n].cls.options_type
        base = given.get(n, kind())
        if not isinstance(base, kind):
            raise TerrabenchError(f"options for {n!r} must be a {kind.__name__}, got {type(base).__name__}")
        out[n] = base.updated(**routed)
    return out
