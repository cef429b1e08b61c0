"""The HTML report a person reads: headline per scene first, then the speed-against-accuracy chart, then the
nested reading, tables each in a scrolling box, '–' for missing values, the environment as a key/value table."""

import math
import shutil
import subprocess
from html.parser import HTMLParser

import numpy as np
import pandas as pd
import pytest

from experiments.report import TITLES, intro, measures, summary_table, write_report
from experiments.report_html import page, reading_html, table_html, value_html
from experiments.report_html_headline import scene_headlines
from experiments.runner import run_spec
from experiments.spec import parse_spec

SPEC = """
name = "html"
datasets = ["fbm"]
dataset_size = 129
flights = ["flyover"]
frames = 2
policies = ["raster", "raycast", "hybrid"]
sizes = ["160x90"]
repeats = 3
tile_size = 32
supersample = 1
flip = true
image_frames = [1]
"""
VOID = {"meta", "img", "br", "hr", "link", "input"}


class Tree(HTMLParser):
    """Every start tag with its attributes and its open ancestors, in document order; fails on a misnested tag."""

    def __init__(self, text: str):
        super().__init__()
        self.stack, self.tags = [], []
        self.feed(text)
        assert self.stack == [], f"unclosed tags {self.stack}"

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs), [t for t, _ in self.stack], [a for _, a in self.stack]))
        if tag not in VOID:
            self.stack.append((tag, dict(attrs)))

    def handle_endtag(self, tag):
        assert self.stack and self.stack[-1][0] == tag, f"</{tag}> closes {self.stack[-1:]}"
        self.stack.pop()


def check_page(text: str, folder=None) -> Tree:
    """The structure every report page has (folder: where its images must exist)."""
    tree = Tree(text)
    assert "NaN" not in text and "nan<" not in text.lower() and "{'" not in text and "{&#x27;" not in text
    head, first_table = text.index("id='headline'"), text.index("<table")
    assert head < text.index("<img") < first_table  # headline, then the chart, then tables
    assert text.index("id='reading'") < text.index("id='summary'") < text.index("id='method'")
    imgs = [a for t, a, _, _ in tree.tags if t == "img"]
    assert imgs and imgs[0]["src"] == "speed_vs_accuracy.png"
    if folder is not None:
        assert all((folder / a["src"]).is_file() for a in imgs)
    for tag, _, _, attrs in tree.tags:  # every table inside a scrolling box
        if tag == "table":
            assert any("scroll" in a.get("class", "").split() for a in attrs)
    return tree


def nested_reading(tree: Tree) -> bool:
    """A <ul> inside an <li> inside the reading's list."""
    return any(
        t == "ul" and "li" in anc and any(a.get("class") == "reading" for a in attrs) for t, _, anc, attrs in tree.tags
    )


def frame_rows(policy, ms, tau, tiles_raster=0, tiles_raycast=10, seed=0, flip=0.01, frames=6):
    """Frame rows of one method with three repeats tightly around ms."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(frames):
        reps = list(ms * (1 + 0.01 * (rng.random(3) - 0.5)))
        out.append(
            {
                "config": f"{policy}{tau}",
                "dataset": "fbm",
                "flight": "orbit",
                "size": "160x90",
                "tau": tau,
                "reconstruction": "triangles",
                "policy": policy,
                "frame": k,
                "wall_ms": float(np.median(reps)),
                "wall_ms_repeats": reps,
                "tiles": tiles_raster + tiles_raycast,
                "tiles_raster": tiles_raster,
                "tiles_raycast": tiles_raycast,
                "tiles_gs": 0,
                "gpu_bytes": 2**20,
                "flip": flip,
                "pop_px": math.nan,
            }
        )
    return out


def synthetic() -> pd.DataFrame:
    """Two taus: at 2/3 px the hybrid is clearly faster than the better pure method, at 2 px it is slower."""
    parts = [
        frame_rows("raster", 30.0, 0.6667, 10, 0, 1),
        frame_rows("raycast", 20.0, 0.6667, seed=2, flip=0.005),
        frame_rows("hybrid", 10.0, 0.6667, 4, 6, 3),
        frame_rows("raster", 8.0, 2.0, 10, 0, 4, flip=0.02),
        frame_rows("raycast", 19.0, 2.0, seed=5),
        frame_rows("hybrid", 16.0, 2.0, 5, 5, 6),
    ]
    return pd.DataFrame([r for p in parts for r in p])


def test_the_headline_names_the_winner_and_the_hybrids_gain_with_its_interval():
    (h,) = scene_headlines(synthetic())
    assert h.fastest == "raster tau=2" and h.accurate == ["raycast tau=0.667"] and h.flip == pytest.approx(0.005)
    gains = {g.hybrid: g for g in h.gains}
    win, loss = gains["hybrid tau=0.667"], gains["hybrid tau=2"]
    assert win.pure == "raycast tau=0.667" and win.verdict == "win" and win.words().startswith("2.00× faster (interval")
    assert loss.pure == "raster tau=2" and loss.verdict == "loss" and "× slower (interval" in loss.words()


def test_a_page_from_a_constructed_table_has_the_reading_order_and_no_raw_values(tmp_path):
    f = synthetic()
    charts = {"frame_time": [tmp_path / "frame_time.png"], "speed_vs_accuracy": [tmp_path / "speed_vs_accuracy.png"]}
    lines = ["**a scene**: fast.", "  a finding.", "  another.", "Adaptation: none."]
    env = {
        "gl_renderer": "llvmpipe",
        "packages": {"terrabench": "0.1.0", "numpy": "2"},
        "cost_model": {"source": "shipped", "sha256": "abc"},
    }
    spec = {"name": "x", "repeats": 3}
    text = page(
        "t",
        "",
        spec,
        env,
        lines,
        summary_table(f),
        charts,
        ["credit"],
        scene_headlines(f),
        intro(spec),
        measures(True),
        TITLES,
    )
    tree = check_page(text)
    assert nested_reading(tree) and "<strong>a scene</strong>" in text
    assert text.index("speed_vs_accuracy.png") < text.index("frame_time.png")  # the top chart, then the rest
    assert "<li><b>terrabench</b> 0.1.0</li>" in text and "shipped (sha256 abc)" in text
    assert "2.00× faster (interval" in text and ">–<" in text  # pop_px missing: a dash


def test_reading_keeps_its_nesting_and_tables_show_a_dash_for_missing_values():
    tree = Tree(reading_html(["top", "  child 1", "  child 2", "next", "  child 3"]))
    nested = [anc for t, _, anc, _ in tree.tags if t == "li" and anc.count("ul") == 2]
    assert len(nested) == 3
    cells = table_html(pd.DataFrame({"m": ["a", "b"], "v": [1.5, math.nan], "n": [3, 4]}))
    assert "NaN" not in cells and "<td class='num'>–</td>" in cells and "class='scroll'" in cells
    assert value_html({"a": {"b": 1}}).count("<ul class='compact'>") == 2 and value_html(None) == "–"


@pytest.fixture(scope="module")
def report(ctx, tmp_path_factory):
    run = run_spec(parse_spec(SPEC), tmp_path_factory.mktemp("runs"), ctx, progress=False)
    return write_report(run, tmp_path_factory.mktemp("reports")).parent


def test_a_tiny_run_makes_a_page_a_person_reads(report):
    text = (report / "report.html").read_text()
    tree = check_page(text, report)
    assert nested_reading(tree)
    assert "Hybrid against the better pure method" in text and "interval" in text.split("id='reading'")[0]
    assert "Packages" in text and "<ul class='compact'>" in text


def _browser() -> str | None:
    return next((b for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None)


@pytest.mark.skipif(_browser() is None, reason="no headless Chromium to lay the page out")
def test_the_page_does_not_overflow_1400_px(report, tmp_path):
    probe = (
        "<script>window.onload=()=>document.body.setAttribute('data-over',"
        "String(document.documentElement.scrollWidth>document.documentElement.clientWidth))</script>"
    )
    page_file = report / "probe.html"
    page_file.write_text((report / "report.html").read_text().replace("</body>", probe + "</body>"))
    out = subprocess.run(
        [
            _browser(),
            "--headless",
            "--disable-gpu",
            "--no-sandbox",
            "--window-size=1400,900",
            "--virtual-time-budget=3000",
            "--dump-dom",
            page_file.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    ).stdout
    assert 'data-over="false"' in out, out[-500:]


def test_without_accuracy_the_frame_time_chart_leads_and_no_accuracy_is_claimed(tmp_path):
    f = synthetic().drop(columns="flip")
    charts = {"frame_time": [tmp_path / "frame_time.png"], "speed_vs_accuracy": []}
    spec = {"name": "x", "repeats": 3, "accuracy": False}
    text = page(
        "t",
        "2 of 9 frames are missing",
        spec,
        {"gl_renderer": ["a", "b"], "workers": {"w1": {"ok": 1}}},
        ["**s**: fast."],
        summary_table(f),
        charts,
        [],
        scene_headlines(f),
        intro(spec),
        measures(False),
        TITLES,
    )
    Tree(text)
    assert text.index("id='headline'") < text.index("frame_time.png") < text.index("<table")
    assert "Most accurate" not in text and "Incomplete:" in text and "<td>a, b</td>" in text
