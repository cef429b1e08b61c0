"""Typed configurations: a Config or an EditConfig round-trips through its row, the journal and pickling, keeps the
row form runs have always written, and a run folder whose journal holds such rows resumes from them."""

import json
import pickle

import pandas as pd

from experiments.journal import Journal, pending
from experiments.run_config import Config, EditConfig
from experiments.runner import run_spec
from experiments.spec import parse_spec

SPEC = """
name = "typed"
datasets = ["fbm"]
dataset_size = 65
flights = ["flyover"]
frames = 2
policies = ["raster", "raycast", "hybrid"]
reconstructions = ["triangles", "planes"]
start_models = ["device", "fallback"]
sizes = ["96x54"]
repeats = 3
tile_size = 32
supersample = 1
image_frames = [0]
flip = false
"""
EDIT_SPEC = """
kind = "edit"
name = "e"
dataset = "fbm"
dataset_size = 65
frames = 2
sizes = ["64x36"]
[edit]
path = [[0.2, 0.2], [0.8, 0.8]]
radii = [500.0, 1500.0]
"""
# a frames.jsonl line in the stored form every run folder holds (the config's keys in this order), which must resume
OLD_FRAME = (
    '{"config": "fbm-s0-flyover-96x54-tau0.6667-triangles-raster-lean", "dataset": "fbm", "seed": 0, '
    '"flight": "flyover", "size": "96x54", "tau": 0.6666666666666666, "reconstruction": "triangles", '
    '"full_res": "lean", "policy": "raster", "start_model": "device", "frame": 0, "wall_ms": 12345.0, '
    '"tiles_rows": []}'
)
OLD_EDIT_KEYS = [
    "config", "dataset", "seed", "flight", "size", "tau", "policy", "editing", "edit_radius", "brush", "particles",
]  # fmt: skip


def test_configs_round_trip_through_rows_the_journal_and_pickling(tmp_path):
    for configs, cls in ((parse_spec(SPEC).configs(), Config), (parse_spec(EDIT_SPEC).configs(), EditConfig)):
        assert configs and all(type(c) is cls for c in configs)
        journal = Journal(tmp_path)
        journal.append(cls.__name__, [{**c.row(), "frame": 0, "wall_ms": 1.5} for c in configs])
        back = [cls.of(r) for r in journal.rows(cls.__name__)]
        assert back == configs  # the frame's own columns are left out
        assert [cls.of(c.row()) for c in configs] == configs
        assert pickle.loads(pickle.dumps(configs)) == configs  # as a cluster task sends them
    assert len({c.config for c in parse_spec(SPEC).configs()}) == len(parse_spec(SPEC).configs())


def test_rows_keep_the_columns_runs_have_always_written():
    old = json.loads(OLD_FRAME)
    spec = parse_spec(SPEC)
    raster = next(c for c in spec.configs() if c.policy == "raster")
    assert list(raster.row()) == list(old)[:10]
    assert raster.row() == {k: old[k] for k in list(old)[:10]}
    assert Config.of(old) == raster
    assert Config.of({k: v for k, v in old.items() if k != "start_model"}) == raster  # runs before start models
    edit = parse_spec(EDIT_SPEC).configs()
    assert [list(c.row()) for c in edit] == [OLD_EDIT_KEYS] * len(edit)
    assert {(c.editing, c.edit_radius, c.brush) for c in edit} == {
        (True, 500.0, "crater"),
        (True, 1500.0, "crater"),
        (False, 0.0, "none"),
    }


def test_pending_reads_a_stored_journal_as_configs(tmp_path):
    spec = parse_spec(SPEC)
    (tmp_path / "frames.jsonl").write_text(OLD_FRAME + "\n")
    todo = pending(spec, Journal(tmp_path))
    assert [c for c, _ in todo] == spec.configs()  # every configuration, as Config values
    frames = {c.config: t for c, t in todo}
    assert frames[json.loads(OLD_FRAME)["config"]] == [1]  # its journaled frame is done
    assert all(t == [0, 1] for cid, t in frames.items() if cid != json.loads(OLD_FRAME)["config"])


def test_a_run_folder_with_a_stored_journal_resumes_from_it(ctx, tmp_path):
    spec = parse_spec(SPEC.replace('policies = ["raster", "raycast", "hybrid"]', 'policies = ["raster"]'))
    folder = tmp_path / "runs" / spec.name
    folder.mkdir(parents=True)
    (folder / "spec.json").write_text(json.dumps(spec.to_dict()))
    (folder / "frames.jsonl").write_text(OLD_FRAME + "\n")
    assert run_spec(spec, tmp_path / "runs", ctx, progress=False) == folder
    f = pd.read_parquet(folder / "frames.parquet").sort_values("frame")
    assert list(f["frame"]) == [0, 1]
    assert f["wall_ms"].iloc[0] == 12345.0 and f["wall_ms"].iloc[1] < 12345.0  # frame 0 kept, not redone
    assert f["config"].nunique() == 1 and Config.of(f.iloc[1].to_dict()) == spec.configs()[0]
