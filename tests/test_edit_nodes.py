"""The raster node arrays after edits on large nodes' posts and borders equal a rebuild, paying for what they touch."""

import numpy as np
import pytest

import raster.node_blocks as nb
import raster.node_edit as ne
import raster.rect_nodes as rn
from hybrid.terrain.datasets import get_dataset
from hybrid.terrain.edits import Crater, Raise, Smooth, apply_brush, brush_params
from raster.node_edit import node_edits, update_nodes
from raster.nodes import GlobalNodes


def _nodes(hf, n, beta):
    R, eff, zlo, zhi, sides = rn.rect_nodes(hf, n, beta)
    return GlobalNodes(
        R, beta, *(tuple(a.copy() for a in arr) for arr in (eff, zlo, zhi)), sides=tuple(a.copy() for a in sides)
    )


def _at(hf, row, col):
    """World (x, y) of sample (row, col)."""
    return hf.origin[0] + col * hf.spacing_x, hf.origin[1] + row * hf.spacing_y


@pytest.mark.parametrize("sub_cells", [4, 32])
def test_edits_on_large_node_posts_and_borders_equal_a_rebuild(monkeypatch, sub_cells):
    monkeypatch.setattr(nb, "SUB_CELLS", sub_cells)
    monkeypatch.setattr(ne, "EXTREME_BLOCK", 24)  # blocks that do not divide the grid
    hf = get_dataset("fbm", 113)  # tiles of 16: a 128-cell square, nodes up to 128 cells
    sp = hf.spacing_x
    top = np.unravel_index(np.argmax(np.abs(hf.heights)), hf.heights.shape)
    nodes, st = _nodes(hf, 16, 0.9), node_edits(hf, 16, 0.9)
    assert set(st.blocks) == {g for g in range(7) if (2 << g) > sub_cells}
    edits = [
        Raise(_at(hf, 64, 64), 1.5 * sp, 50.0),  # the 128-cell node's centre post only
        Crater(_at(hf, 64, 64), 5 * sp, 30.0),  # and around it: four 64-cell nodes' corner
        Raise(_at(hf, 32, 96), 0.9 * sp, -40.0),  # one sample: a 64-cell node's centre post
        Smooth(_at(hf, 64, 20), 3 * sp, 1.0),  # across a large node's border, no post column
        Raise(_at(hf, 112, 112), 4 * sp, 25.0),  # the grid's corner: padding classes beyond it
        Crater(_at(hf, *top), 3 * sp, 40.0),  # lowers the largest |height|: the margin moves
    ]
    for brush in edits:
        win = apply_brush(hf.heights, brush_params(brush, hf))
        update_nodes(st, nodes, hf, win)
        want = rn.rect_nodes(hf, 16, 0.9)
        for got_arrays, want_arrays in zip((nodes.effective, nodes.zlo, nodes.zhi, nodes.sides), want[1:], strict=True):
            for g, (a, b) in enumerate(zip(got_arrays, want_arrays, strict=True)):
                np.testing.assert_array_equal(a, b, err_msg=f"level {g} after {brush}")
        fresh = node_edits(hf, 16, 0.9)
        np.testing.assert_array_equal(st.extremes, fresh.extremes, err_msg=f"after {brush}")
        assert st.margin == 16 * np.finfo(np.float64).eps * max(float(np.abs(hf.heights).max()), 1.0)
        for g, vals in st.blocks.items():  # the kept maxima equal a fresh measurement
            np.testing.assert_array_equal(vals, fresh.blocks[g], err_msg=f"level {g} after {brush}")


def test_an_edit_away_from_posts_measures_only_its_sub_blocks(monkeypatch):
    hf = get_dataset("fbm", 129)
    nodes, st = _nodes(hf, 16, 0.9), node_edits(hf, 16, 0.9)
    measured = []
    real = nb._measure

    def counting(h, g, R, side_errors, rows, cols):
        measured.append((g, (rows[1] - rows[0]) * (cols[1] - cols[0])))
        return real(h, g, R, side_errors, rows, cols)

    monkeypatch.setattr(nb, "_measure", counting)
    win = apply_brush(hf.heights, brush_params(Raise(_at(hf, 40, 75), 3 * hf.spacing_x, 20.0), hf))
    assert not any(i % 16 == 0 for i in range(win.i0, win.i1))  # no post of a node of 32 cells or more
    assert not any(j % 16 == 0 for j in range(win.j0, win.j1))
    update_nodes(st, nodes, hf, win)
    large = [cells for g, cells in measured if g in st.blocks]
    assert large and max(large) <= (2 * nb.SUB_CELLS) ** 2 and sum(large) < 128 * 128 // 4
    np.testing.assert_array_equal(nodes.effective[6], rn.rect_nodes(hf, 16, 0.9)[1][6])
