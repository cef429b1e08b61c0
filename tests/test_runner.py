"""The experiment runner end to end on a tiny spec: tables, charts, report, resume, failures, bad specs."""

import json

import pandas as pd
import pytest

from experiments.report import write_report
from experiments.runner import run_spec
from experiments.spec import load_spec, parse_spec
from hybrid.contract import DEFAULT_FULL_RES
from hybrid.cost.model import load_cost_model
from hybrid.errors import TerrabenchError
from hybrid.strategies import policies_taking

TINY = """
name = "t"
datasets = ["fbm"]
dataset_size = 129
flights = ["flyover"]
frames = 3
policies = ["raster", "raycast", "hybrid"]
sizes = ["160x90"]
repeats = 3
tile_size = 32
supersample = 1
image_frames = [1]
"""


@pytest.fixture(scope="module")
def run(ctx, tmp_path_factory):
    base = tmp_path_factory.mktemp("runs")
    folder = run_spec(parse_spec(TINY), base, ctx, progress=False)
    return base, folder


def test_tables_have_expected_rows_and_columns(run):
    _, folder = run
    f = pd.read_parquet(folder / "frames.parquet")
    assert len(f) == 3 * 3 and set(f["policy"]) == {"raster", "raycast", "hybrid"}
    for col in (
        "wall_ms",
        "plan_ms",
        "draw_ms",
        "gpu_bytes",
        "hole_px",
        "extra_px",
        "crack_px",
        "silhouette_px",
        "terrain_as_sky",
        "depth_rel_median",
        "depth_rel_p99",
        "depth_rel_max",
        "psnr",
        "ssim",
        "flip",
        "change_ratio",
        "error_flicker",
        "flow_px",
        "tiles",
    ):
        assert col in f, col
    assert f["wall_ms"].gt(0).all() and f["gpu_bytes"].gt(0).all()
    assert (f["gpu_bytes"] - f["shared_bytes"]).le(256 << 20).all() and f["fallback_tiles"].eq(0).all()
    # every repeat kept, the median reported
    assert all(len(r) == 3 and min(r) <= m <= max(r) for r, m in zip(f["wall_ms_repeats"], f["wall_ms"]))
    assert (f["silhouette_px"] + f["crack_px"] == f["hole_px"] + f["extra_px"]).all()
    assert f.loc[f["frame"] > 0, "error_flicker"].notna().all()
    # popping needs a frame either side, and a slow camera: the 3-frame flyover moves the image far
    assert f.loc[f["frame"] == 1, "flow_px"].gt(2).all() and f.loc[f["frame"] != 1, "flow_px"].isna().all()
    assert f["pop_px"].isna().all()
    h = f[f["policy"] == "hybrid"]
    assert (h["tiles_raster"] + h["tiles_raycast"] == h["tiles"]).all()
    assert f.loc[f["policy"] == "raycast", "rays"].gt(0).all()
    assert f.loc[f["policy"] == "raster", "triangles"].gt(0).all()
    t = pd.read_parquet(folder / "tiles.parquet")
    assert len(t) == int(h["tiles"].sum())  # one row per hybrid tile and frame
    assert set(t["strategy"]) <= {"raster", "raster_gs", "raycast"} and t["pred_raycast_ms"].notna().all()
    assert (folder / "images" / "ref-fbm-s0-flyover-160x90-f1.png").exists()
    assert (folder / "images" / "fbm-s0-flyover-160x90-tau0.6667-triangles-hybrid-lean-f1.strategy.npy").exists()


def test_report_and_charts(run, tmp_path):
    _, folder = run
    md = write_report(folder, tmp_path)
    text = md.read_text()
    for part in (
        "## Environment",
        "GL renderer:",
        "## Reading",
        "## Summary",
        "frame_time.png",
        "speed_vs_accuracy.png",
        "Terrain: synthetic only",
    ):
        assert part in text, part
    assert "Puget Sound" not in text and "Puget Sound" not in (md.parent / "report.html").read_text()  # not used here
    for name in ("frame_time", "gpu_memory", "speed_vs_accuracy", "strategy_mix", "images_fbm_flyover_160x90_f1"):
        assert (md.parent / f"{name}.png").stat().st_size > 5000 and (md.parent / f"{name}.svg").exists()
    assert (md.parent / "report.html").read_text().count("<img") >= 5
    assert "after one untimed warm-up frame" in text and "cracks_px" in text and "noise_%" in text
    model = load_cost_model(json.loads((folder / "env.json").read_text())["gl_renderer"])
    assert f"- Hybrid cost model: {model.source} (sha256 " in text
    assert f"its raster frames drawn with full_res {model.full_res!r})" in text
    assert not (md.parent / "popping.png").exists()  # nothing measured on a fast flight, no empty chart


def test_interrupted_run_resumes_without_redoing(run, ctx):
    base, folder = run
    journal = folder / "frames.jsonl"
    lines = journal.read_text().splitlines()
    kept, dropped = lines[:-2], lines[-2:]  # as if killed during the last configuration
    journal.write_text("\n".join(kept) + "\n" + dropped[0][:17])  # and a torn last line
    before = {(json.loads(l)["config"], json.loads(l)["frame"]): json.loads(l)["wall_ms"] for l in kept}
    run_spec(parse_spec(TINY), base, ctx, progress=False)
    rows = [json.loads(l) for l in journal.read_text().splitlines() if l.startswith("{") and l.endswith("}")]
    keys = [(r["config"], r["frame"]) for r in rows]
    assert len(keys) == len(set(keys)) == 9  # nothing twice, nothing missing
    for r in rows:
        if (r["config"], r["frame"]) in before:
            assert r["wall_ms"] == before[(r["config"], r["frame"])]  # finished rows were not redone
    assert len(pd.read_parquet(folder / "frames.parquet")) == 9


def test_failed_configuration_is_recorded(ctx, tmp_path):
    broken = tmp_path / "broken.tif"
    broken.write_bytes(b"not a raster")  # there, so the run starts; each of its configs fails
    spec = parse_spec(
        TINY.replace('datasets = ["fbm"]', f'datasets = ["fbm", "{broken}"]')
        .replace("frames = 3", "frames = 2")
        .replace("image_frames = [1]", "image_frames = [0]")
    )
    folder = run_spec(spec, tmp_path, ctx, progress=False)
    errors = [json.loads(l) for l in (folder / "errors.jsonl").read_text().splitlines()]
    assert errors and all("broken.tif" in e["error"] for e in errors)
    assert len(pd.read_parquet(folder / "frames.parquet")) == 3 * 2  # the rest went on


def test_a_run_from_before_full_res_resumes_and_reports(run, ctx, tmp_path):
    import json
    import shutil

    _base, folder = run
    old = tmp_path / "runs" / folder.name
    shutil.copytree(folder, old)
    stored = json.loads((old / "spec.json").read_text())
    del stored["full_res"]  # as runs wrote it before specs had the key
    (old / "spec.json").write_text(json.dumps(stored))
    with pytest.raises(TerrabenchError, match="different spec"):  # it drew by the exact rule
        run_spec(parse_spec(TINY), tmp_path / "runs", ctx, progress=False)
    assert run_spec(parse_spec(TINY + 'full_res = ["exact"]\n'), tmp_path / "runs", ctx, progress=False) == old
    frames = pd.read_parquet(old / "frames.parquet")
    frames.drop(columns=["full_res"]).to_parquet(old / "frames.parquet")
    text = write_report(old, tmp_path / "reports").read_text()
    assert "raster" in text and "/nan" not in text and "/exact" not in text


def test_other_spec_refuses_existing_folder(run, ctx):
    base, _ = run
    with pytest.raises(TerrabenchError, match="different spec"):
        run_spec(parse_spec(TINY.replace("repeats = 3", "repeats = 4")), base, ctx, progress=False)


@pytest.mark.parametrize(
    "text, match",
    [
        ("frames = [", "not valid TOML"),
        ("colour = 1", "unknown keys"),
        ('policies = ["fastest"]', "unknown policy"),
        ("taus = [0]", "tau must lie"),
        ('sizes = ["0x10"]', "width and height"),
        ("frames = 0", "'frames' must be an integer"),
        ("repeats = 2", r"'repeats' must be an integer in \[3,"),
        ("tile_size = 100", "power of two"),
        ('reconstructions = ["cubic"]', "unknown reconstruction"),
        ('full_res = ["half"]', "unknown full_res 'half'; choose from exact, lean"),
        ('full_res = ["lean", "lean"]', "'full_res' lists 'lean' more than once"),
        ("image_frames = [99]", "outside"),
        ('name = "a/b"', "name must be"),
        ("seeds = [-1]", "seeds must lie in"),
        ('policies = ["raster", "raycast", "raster"]', "'policies' lists 'raster' more than once"),
        ("taus = [2.0, 2.0]", "'taus' lists 2.0 more than once"),
        ("gpu_budget_mib = 0", r"'gpu_budget_mib' must be an integer in \[1,"),
        ("upload_budget_ms = -1", "'upload_budget_ms' must be a number of ms"),
        ('upload_budget_ms = "fast"', "'upload_budget_ms' must be a number of ms"),
    ],
)
def test_bad_specs(text, match):
    with pytest.raises(TerrabenchError, match=match):
        parse_spec(text)


def test_full_resolution_rules_vary_only_tilelet_policies():
    spec = parse_spec(
        'policies = ["raster", "raster_gs", "raycast", "hybrid", "reference"]\nfull_res = ["exact", "lean"]'
    )
    rules = {}
    for c in spec.configs():
        rules.setdefault(c.policy, []).append(c.full_res)
    assert rules == {
        "raster": ["exact", "lean"],
        "raster_gs": ["exact", "lean"],
        "hybrid": ["exact", "lean"],
        "raycast": ["exact"],
        "reference": ["exact"],
    }
    ids = [c.config for c in spec.configs()]
    assert len(set(ids)) == len(ids) and sum(i.endswith("-lean") for i in ids) == 3
    assert {c.full_res for c in parse_spec("").configs() if c.policy in policies_taking("full_res")} == {
        DEFAULT_FULL_RES
    }


def test_a_run_compares_both_full_resolution_rules(ctx, tmp_path):
    spec = parse_spec(TINY.replace('name = "t"', 'name = "fr"') + 'full_res = ["exact", "lean"]\n')
    folder = run_spec(spec, tmp_path / "runs", ctx, progress=False)
    frames = pd.read_parquet(folder / "frames.parquet")
    tri = frames[frames["policy"] == "raster"].groupby("full_res")["triangles"].sum()
    assert set(frames[frames["policy"] == "raycast"]["full_res"]) == {"exact"}
    assert 0 < tri["lean"] < tri["exact"]  # full-resolution leaves drop midpoints too
    text = write_report(folder, tmp_path / "reports").read_text()
    assert "raster/lean" in text and "hybrid/lean" in text and "raster/exact" in text


def test_a_slow_flight_measures_popping_beside_its_held_floor(ctx, tmp_path):
    """On the dolly every method's middle frames get pop_px and pop_static_px (its level of detail held over the
    three frames); the report's table and chart show both."""
    spec = parse_spec(
        TINY.replace('name = "t"', 'name = "pop"')
        .replace('"flyover"', '"dolly"')
        .replace('["raster", "raycast", "hybrid"]', '["raster", "raycast"]')
    )
    folder = run_spec(spec, tmp_path / "runs", ctx, progress=False)
    f = pd.read_parquet(folder / "frames.parquet")
    mid = f[f["frame"] == 1]
    assert mid["flow_px"].le(2).all() and mid["pop_px"].notna().all() and mid["pop_static_px"].notna().all()
    assert f.loc[f["frame"] != 1, "pop_static_px"].isna().all()
    text = write_report(folder, tmp_path / "reports").read_text()
    assert "pop_static_px" in text and "Popping" in text
    assert list((tmp_path / "reports").rglob("popping*.png"))


def test_bundled_specs_parse():
    for name in ("default", "tiny", "full-res"):
        assert load_spec(name).configs()
        assert load_spec(name).gpu_budget_mib == 256 and load_spec(name).upload_budget_ms is None
    rules = {(c.policy, c.full_res) for c in load_spec("full-res").configs()}
    assert {("raster", "lean"), ("hybrid", "lean"), ("raster", "exact")} <= rules
    with pytest.raises(TerrabenchError, match="no such spec"):
        load_spec("nowhere.toml")


def test_report_needs_a_run(tmp_path):
    with pytest.raises(TerrabenchError, match="not a run folder"):
        write_report(tmp_path, tmp_path)


def test_video_animation(ctx, tmp_path):
    from PIL import Image

    spec = parse_spec(
        TINY.replace('policies = ["raster", "raycast", "hybrid"]', 'policies = ["raster", "raycast"]')
        + "video = true\n"
    )
    folder = run_spec(spec, tmp_path / "runs", ctx, progress=False)
    md = write_report(folder, tmp_path / "reports", video=True)
    gifs = list(md.parent.glob("flight_*.gif"))
    assert len(gifs) == 1 and gifs[0].name in md.read_text()
    with Image.open(gifs[0]) as im:
        assert im.n_frames == 3
        assert im.size == (3 * 160, 90)  # reference + two methods side by side


def test_stress_spec_runs_through_the_runner(ctx, tmp_path, capsys):
    from experiments.cli import main

    spec = tmp_path / "s.toml"
    spec.write_text(
        'kind = "stress"\nname = "s"\nscenes = ["spike"]\nviews = ["grazing", "down"]\n'
        'methods = ["raster", "raycast/triangles"]\nsize_samples = 65\nsize = "96x54"\ntile_size = 16\n'
    )
    assert (
        main(
            [
                "run",
                str(spec),
                "--runs",
                str(tmp_path / "runs"),
                "--report",
                "--reports",
                str(tmp_path / "rep"),
                "--quiet",
            ]
        )
        == 0
    )
    df = pd.read_parquet(tmp_path / "runs" / "s" / "stress.parquet")
    assert len(df) == 4 and (df["error"] == "").all()
    assert (tmp_path / "rep" / "s" / "stress.md").exists() and (tmp_path / "rep" / "s" / "stress_failures.png").exists()
    assert main(["report", str(tmp_path / "runs" / "s"), "--reports", str(tmp_path / "rep2")]) == 0
    assert (tmp_path / "rep2" / "s" / "stress.md").exists()
    with pytest.raises(TerrabenchError, match="unknown views"):
        parse_spec('kind = "stress"\nviews = ["sideways"]')
    with pytest.raises(TerrabenchError, match="kind must be"):
        parse_spec('kind = "party"')
    assert load_spec("stress").methods


def test_a_streaming_spec_reports_uploads_and_fallbacks_inside_its_budgets(ctx, tmp_path):
    text = (
        TINY.replace('policies = ["raster", "raycast", "hybrid"]', 'policies = ["raycast"]')
        + "gpu_budget_mib = 1\nupload_budget_ms = 0\n"
    )
    folder = run_spec(parse_spec(text), tmp_path, ctx, progress=False)
    f = pd.read_parquet(folder / "frames.parquet")
    assert (f["gpu_bytes"] - f["shared_bytes"]).le(1 << 20).all()
    assert f["upload_ms"].ge(0).all() and f["fallback_tiles"].ge(0).all() and "pending_uploads" in f


def test_a_groups_configurations_are_timed_interleaved_in_rotating_order(ctx, tmp_path, monkeypatch):
    import hybrid.renderer as renderers

    draws, make = [], renderers.make_renderer

    def logged(ctx, hf, policy, **kw):  # the real renderer, its draws logged in the order they happen
        r = make(ctx, hf, policy, **kw)
        render = r.render
        r.render = lambda view, tau, **k: draws.append((policy, k.get("maps", False))) or render(view, tau, **k)
        return r

    monkeypatch.setattr(renderers, "make_renderer", logged)
    folder = run_spec(parse_spec(TINY), tmp_path, ctx, progress=False)
    policies = ["raster", "raycast", "hybrid"]
    assert draws[:3] == [(p, False) for p in policies]  # one untimed warm-up draw each
    timed = [p for p, maps in draws[3:] if not maps]
    assert [p for p, maps in draws if maps] == ["hybrid"]  # one untimed maps draw, for the image frame
    rounds = [timed[i : i + 3] for i in range(0, len(timed), 3)]
    assert len(rounds) == 3 * 3 and all(sorted(r) == sorted(policies) for r in rounds)  # frames x repeats
    assert [r[0] for r in rounds] == [policies[i % 3] for i in range(9)]  # the first of a round rotates
    f = pd.read_parquet(folder / "frames.parquet")
    assert len(f) == 9 and (f["wall_ms_repeats"].map(len) == 3).all()


def test_a_configuration_failing_in_its_measures_keeps_its_groups_reference_images(ctx, tmp_path, monkeypatch):
    import experiments.config_task as task

    accuracy, calls = task.frame_accuracy, []

    def first_fails(res, ref, **kw):  # raster's frame 1, after that image frame's reference is rendered
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("measure failed")
        return accuracy(res, ref, **kw)

    monkeypatch.setattr(task, "frame_accuracy", first_fails)
    folder = run_spec(parse_spec(TINY), tmp_path, ctx, progress=False)
    errors = [json.loads(l) for l in (folder / "errors.jsonl").read_text().splitlines()]
    assert [e["policy"] for e in errors] == ["raster"] and "measure failed" in errors[0]["error"]
    assert len(pd.read_parquet(folder / "frames.parquet")) == 2 * 3  # the other two went on
    assert (folder / "images" / "ref-fbm-s0-flyover-160x90-f1.png").stat().st_size > 1000


def test_start_models_vary_only_the_hybrid():
    spec = parse_spec('policies = ["raster", "raycast", "hybrid"]\nstart_models = ["device", "fallback"]')
    hy = [c for c in spec.configs() if c.policy == "hybrid"]
    assert sorted(c.start_model for c in hy) == ["device", "fallback"]
    assert sum(c.config.endswith("-from-fallback") for c in spec.configs()) == 1
    assert all(c.start_model == "device" for c in spec.configs() if c.policy != "hybrid")
    with pytest.raises(TerrabenchError, match="unknown start model 'h200'"):
        parse_spec('start_models = ["h200"]')
    with pytest.raises(TerrabenchError, match="'adapt' must be true or false"):
        parse_spec('adapt = "yes"')


def test_a_frozen_hybrid_chooses_alike_in_two_runs_and_a_run_before_adapt_resumes_frozen(ctx, tmp_path):
    import json

    frozen = (
        TINY.replace('policies = ["raster", "raycast", "hybrid"]', 'policies = ["hybrid"]')
        + 'adapt = false\nstart_models = ["fallback"]\n'
    )
    tiles = []
    for name in ("a", "b"):
        folder = run_spec(parse_spec(frozen), tmp_path / name, ctx, progress=False)
        tiles.append(pd.read_parquet(folder / "tiles.parquet").sort_values(["frame", "level", "tx", "ty"]))
    assert len(tiles[0]) and list(tiles[0]["strategy"]) == list(tiles[1]["strategy"])
    assert (tiles[0]["config"].str.endswith("-from-fallback")).all()
    stored = json.loads((folder / "spec.json").read_text())
    del stored["adapt"]  # as runs wrote it before the hybrid adapted
    (folder / "spec.json").write_text(json.dumps(stored))
    assert run_spec(parse_spec(frozen), tmp_path / "b", ctx, progress=False) == folder
    with pytest.raises(TerrabenchError, match="different spec"):
        run_spec(parse_spec(frozen.replace("adapt = false", "adapt = true")), tmp_path / "b", ctx, progress=False)
