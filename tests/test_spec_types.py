"""A flights spec's keys are checked against the types its ``Spec`` dataclass declares: a value of another type is
refused by name for every key, and list entries take the field's entry type."""

from dataclasses import fields
from typing import get_origin, get_type_hints

import pytest

from experiments.spec import Spec, parse_spec
from hybrid.errors import TerrabenchError


@pytest.mark.parametrize("key", [f.name for f in fields(Spec) if f.name != "name"])
def test_every_spec_key_refuses_a_value_of_another_type(key):
    hint = get_type_hints(Spec)[key]
    bad = "[true]" if get_origin(hint) is list else '"x"'  # no list key takes booleans, no scalar key text
    with pytest.raises(TerrabenchError, match=key.rstrip("s")):
        parse_spec(f"{key} = {bad}")


def test_list_entries_take_the_fields_entry_type():
    spec = parse_spec("taus = [1, 0.5]\nseeds = [3]\nflip = false\nvideo = false\nadapt = false")
    assert spec.taus == [1.0, 0.5] and all(type(t) is float for t in spec.taus)
    assert spec.seeds == [3] and (spec.flip, spec.video, spec.adapt) == (False, False, False)
    with pytest.raises(TerrabenchError, match="'seeds' entries must be int"):
        parse_spec("seeds = [1.5]")
    with pytest.raises(TerrabenchError, match="'flights' entries must be str"):
        parse_spec("flights = [3]")
