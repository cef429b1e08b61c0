"""Shader layout constants and bindings are defined once, in Python, and reach the GLSL only as defines."""

import re
from importlib import resources

import pytest

from raster.arena import LAYOUTS, LEAF_SIZES
from raster.selection import LEAF_FORMAT, LEAN_LEAF_FORMAT, select_defines


def _source(name: str) -> str:
    return (resources.files("raster") / name).read_text()


@pytest.mark.parametrize("full_res", sorted(LEAF_SIZES))
def test_the_selection_shader_defines_none_of_its_injected_names(full_res):
    names = set(select_defines(full_res, 0)) - {"PASS", "TILE_BLOCKS_STORAGE", "LEAN_FULL_RES", "TURN_FROM"}
    for glsl in ("select.comp.glsl", "select_append.glsl", "tile_block.glsl"):
        text = _source(glsl)
        own = re.findall(r"(?:#define|const\s+\w+)\s+(\w+)", text)
        assert not names & set(own), f"{glsl} defines {sorted(names & set(own))} itself"
        assert not re.search(r"std430,\s*binding\s*=\s*\d", text), f"{glsl} numbers a storage binding itself"


def test_leaf_records_match_their_vertex_formats():
    words = {"exact": LEAF_FORMAT, "lean": LEAN_LEAF_FORMAT}
    for rule, fmt in words.items():
        n = sum(int(t[:-1]) for t in fmt.split())
        assert LEAF_SIZES[rule][0] == n and LAYOUTS[rule][0] == 4 * n
