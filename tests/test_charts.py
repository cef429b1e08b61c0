"""Chart layout from 1 to 20 panels: panel titles, axis labels and the figure legend never overlap; the
strategy-mix chart writes one panel per mixed method and scene."""

import numpy as np
import pandas as pd
import pytest

from experiments.charts import label_columns, strategy_mix_chart
from experiments.figures import figure_legend, panel_grid, panel_title


def _overlaps(boxes):
    return [(i, j) for i in range(len(boxes)) for j in range(i + 1, len(boxes)) if boxes[i].overlaps(boxes[j])]


@pytest.mark.parametrize("n", [1, 4, 12, 20])
def test_panels_titles_and_legend_do_not_overlap(n):
    import matplotlib.pyplot as plt

    fig, axes = panel_grid(n, width=4.2, height=2.6)
    assert len(axes) == n
    for i, ax in enumerate(axes):
        ax.bar(range(8), np.arange(8), label="raster")
        ax.bar(range(8), np.ones(8), bottom=np.arange(8), label="ray cast")
        panel_title(ax, f"hybrid tau=0.667\npuget / flyover-with-a-long-name-{i} / 640x360", 4)
        ax.set_xlabel("frame")
        ax.set_ylabel("tiles")
    figure_legend(fig, axes)
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    boxes = [ax.get_tightbbox(r) for ax in axes] + [fig.legends[0].get_window_extent(r)]
    assert not _overlaps(boxes)
    plt.close(fig)


def test_strategy_mix_has_a_panel_per_mixed_method_and_scene(tmp_path):
    from PIL import Image

    rows = [
        {
            "dataset": "puget",
            "flight": fl,
            "size": "640x360",
            "tau": tau,
            "reconstruction": "triangles",
            "policy": pol,
            "frame": k,
            "tiles": 10,
            "tiles_raster": k,
            "tiles_raycast": 10 - k,
        }
        for fl in ("flyover", "orbit")
        for tau in (0.6667, 2.0)
        for pol in ("hybrid", "heuristic", "oracle", "raster")
        for k in range(8)
    ]
    paths = strategy_mix_chart(label_columns(pd.DataFrame(rows)), tmp_path)
    png = next(p for p in paths if p.suffix == ".png")
    with Image.open(png) as im:
        w, h = im.size
    assert w > h  # 12 panels in rows of 4, not one tall column
    assert png.with_suffix(".svg").read_text().count("heuristic tau=2") == 2  # one title per flight


def test_methods_name_the_full_resolution_rule_only_where_a_run_draws_both():
    def methods(rules):
        rows = [
            {
                "dataset": "puget",
                "flight": "orbit",
                "size": "640x360",
                "tau": 0.6667,
                "reconstruction": "triangles",
                "policy": pol,
                "full_res": fr,
            }
            for pol in ("raster", "hybrid")
            for fr in rules
        ]
        rows.append({**rows[0], "policy": "raycast", "full_res": "exact"})  # ray casting records "exact"
        return sorted(label_columns(pd.DataFrame(rows))["method"])

    assert methods(["lean"]) == ["hybrid", "raster", "raycast"]
    assert methods(["exact"]) == ["hybrid", "raster", "raycast"]
    assert methods(["exact", "lean"]) == ["hybrid/exact", "hybrid/lean", "raster/exact", "raster/lean", "raycast"]
