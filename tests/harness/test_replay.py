"""`trustroute replay`: a finished SUMO study's episodes replay exactly; other code or logs fail loudly."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from tests.cli import run_cli
from tests.harness.helpers import run_study


@pytest.fixture(scope="module")
def sumo_study(tmp_path_factory):
    root = tmp_path_factory.mktemp("replay")
    cache = tmp_path_factory.mktemp("policies")
    run_study(root / "study.toml", f"""[study]
name = "replay-fixture"
participants = 2
seed = 9
engine = "sumo"
specs = ["phi1", "phi2"]
conditions = ["aware", "free"]
policy_cache = "{cache}"
record = ["p00001-phi1-free"]
[population]
concentration = 40.0
takeover_spread = 0.5
""", root / "out")
    return root / "out"


def _copy(study, tmp_path):
    target = tmp_path / "copy"
    shutil.copytree(study, target)
    return target


@pytest.mark.slow
def test_replay_of_a_random_episode_reproduces_roads_and_trust(sumo_study, tmp_path, capsys):
    episodes = pd.read_parquet(sumo_study / "episodes.parquet")
    episode_id = str(np.random.default_rng(13).choice(episodes["episode_id"].to_numpy()))
    rrd = tmp_path / "replay.rrd"
    code, out, err = run_cli(capsys, "replay", str(sumo_study), episode_id, "--rrd", str(rrd), "--json")
    assert code == 0, err
    payload = json.loads(out)
    logged = pd.read_parquet(sumo_study / "roads.parquet")
    logged = logged[logged["episode_id"] == episode_id].sort_values("index")
    assert payload["route"] == logged["directed_road"].tolist()
    assert payload["trust"] == logged["trust_after"].tolist()
    assert rrd.stat().st_size == payload["rrd_bytes"] > 10_000


@pytest.mark.slow
def test_every_episode_of_the_study_replays_exactly(sumo_study):
    from trustroute.harness.study.replay import replay_episode

    episodes = pd.read_parquet(sumo_study / "episodes.parquet")
    assert len(episodes) == 8
    for episode_id in episodes["episode_id"]:
        replay = replay_episode(sumo_study, episode_id)  # raises InputError on any difference
        assert replay.record.roads["trust_after"].tolist() == replay.logged_roads["trust_after"].tolist()


@pytest.mark.slow
def test_config_named_episode_was_recorded_during_the_run(sumo_study):
    import rerun as rr

    path = sumo_study / "recordings" / "p00001-phi1-free.rrd"
    paths = {c.entity_path for c in rr.chunk.RrdReader(path).stream().to_chunks()}
    assert "/world/ego/box" in paths and "/events" in paths
    assert sorted(p.name for p in (sumo_study / "recordings").iterdir()) == ["p00001-phi1-free.rrd"]


@pytest.mark.slow
def test_replay_of_a_study_made_with_other_code_fails(sumo_study, tmp_path, capsys):
    study = _copy(sumo_study, tmp_path)
    manifest = json.loads((study / "manifest.json").read_text())
    manifest["packages"]["trustroute"] = "0.0.1"
    (study / "manifest.json").write_text(json.dumps(manifest))
    code, out, err = run_cli(capsys, "replay", str(study), "p00000-phi1-aware", "--no-rrd")
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "made with trustroute 0.0.1" in err and "Traceback" not in err


def _tamper_trust(study, episode_id, index):
    """Change the logged trust after road `index` of `episode_id` by one level."""
    from trustroute.core.dataset import (
        ROADS_FILE,
        ROADS_SCHEMA,
        read_roads,
        table_from_frame,
        write_table,
    )

    roads = read_roads(study)
    row = roads.index[(roads["episode_id"] == episode_id) & (roads["index"] == index)][0]
    logged = int(roads.loc[row, "trust_after"])
    roads.loc[row, "trust_after"] = logged + 1 if logged < 7 else logged - 1
    write_table(table_from_frame(roads, ROADS_SCHEMA), study / ROADS_FILE)


@pytest.mark.slow
def test_replay_that_differs_from_the_log_fails(sumo_study, tmp_path, capsys):
    study = _copy(sumo_study, tmp_path)
    _tamper_trust(study, "p00000-phi2-free", 2)
    code, _, err = run_cli(capsys, "replay", str(study), "p00000-phi2-free", "--no-rrd")
    assert code == 2 and "does not reproduce the log: road 2 trust_after" in err


@pytest.mark.slow
def test_failed_replay_keeps_the_recording_and_writes_none(sumo_study, tmp_path, capsys):
    study = _copy(sumo_study, tmp_path)
    recordings = study / "recordings"
    recorded = (recordings / "p00001-phi1-free.rrd").read_bytes()
    for episode_id in ("p00001-phi1-free", "p00000-phi2-free"):   # with and without a recording
        _tamper_trust(study, episode_id, 2)
        code, _, err = run_cli(capsys, "replay", str(study), episode_id)
        assert code == 2 and "does not reproduce the log: road 2 trust_after" in err
    assert sorted(p.name for p in recordings.iterdir()) == ["p00001-phi1-free.rrd"]
    assert (recordings / "p00001-phi1-free.rrd").read_bytes() == recorded


def test_replay_bad_input(tmp_path, capsys, monkeypatch):
    code, _, err = run_cli(capsys, "replay", str(tmp_path), "p00000-phi1-aware")
    assert code == 2 and "not a finished study directory" in err


@pytest.mark.slow
def test_replay_unknown_episode_and_gui_without_display(sumo_study, capsys, monkeypatch):
    code, _, err = run_cli(capsys, "replay", str(sumo_study), "p00042-phi1-aware")
    assert code == 2 and "not an episode of this study" in err
    monkeypatch.delenv("DISPLAY", raising=False)
    code, _, err = run_cli(capsys, "replay", str(sumo_study), "p00000-phi1-aware", "--gui", "--no-rrd")
    assert code == 2 and "no display" in err and err.count("\n") == 1


@pytest.fixture(scope="module")
def model_study(tmp_path_factory):
    root = tmp_path_factory.mktemp("replay-model")
    run_study(root / "study.toml", f"""[study]
name = "replay-model"
participants = 2
seed = 1
engine = "model"
specs = ["phi1"]
conditions = ["aware", "free"]
horizon = 6
policy_cache = "{tmp_path_factory.mktemp("policies")}"
""", root / "out")
    return root / "out"


def _tamper(study, table, episode_id, column, change, index=3):
    """Change `column` of `episode_id`'s row in episodes.parquet, or of its road `index` in
    roads.parquet, by `change` (old value -> new value)."""
    from trustroute.core import dataset

    episodes = (dataset.read_episodes, dataset.EPISODES_SCHEMA, dataset.EPISODES_FILE)
    roads = (dataset.read_roads, dataset.ROADS_SCHEMA, dataset.ROADS_FILE)
    read, schema, name = episodes if table == "episodes" else roads
    frame = read(study)
    chosen = frame["episode_id"] == episode_id
    if table == "roads":
        chosen &= frame["index"] == index
    row = frame.index[chosen][0]
    frame.at[row, column] = change(frame.at[row, column])
    dataset.write_table(dataset.table_from_frame(frame, schema), study / name)


@pytest.mark.parametrize(("table", "column", "change"), [
    ("roads", "performance", lambda v: "fail" if v == "succ" else "succ"),
    ("roads", "action", lambda v: "Z"),
    ("roads", "fallback", lambda v: not v),
    ("roads", "sim_time_in", lambda v: 7.5),
    ("roads", "belief_before", lambda v: [float(v[0]) + 1e-6, *v[1:]]),
    ("episodes", "satisfied", lambda v: not v),
    ("episodes", "end_reason", lambda v: "rejected"),
    ("episodes", "takeovers", lambda v: v + 7),
    ("episodes", "mean_trust", lambda v: v + 1e-9),
])
def test_replay_compares_every_logged_column(model_study, tmp_path, capsys, table, column, change):
    study = _copy(model_study, tmp_path)
    _tamper(study, table, "p00001-phi1-free", column, change)
    code, out, err = run_cli(capsys, "replay", str(study), "p00001-phi1-free", "--no-rrd")
    where = f"road 3 {column}" if table == "roads" else f"episodes.parquet {column}"
    assert code == 2 and out == "" and f"does not reproduce the log: {where}" in err, err


def test_replay_ignores_the_wall_clock(model_study, tmp_path, capsys):
    study = _copy(model_study, tmp_path)
    _tamper(study, "episodes", "p00001-phi1-free", "wall_seconds", lambda v: v + 99.0)
    code, out, err = run_cli(capsys, "replay", str(study), "p00001-phi1-free", "--no-rrd")
    assert code == 0 and "replay reproduces the log" in out, err


def test_replay_refuses_a_changed_config_in_the_manifest(model_study, tmp_path, capsys):
    study = _copy(model_study, tmp_path)
    manifest = json.loads((study / "manifest.json").read_text())
    manifest["config"]["seed"] = 2
    (study / "manifest.json").write_text(json.dumps(manifest))
    code, _, err = run_cli(capsys, "replay", str(study), "p00001-phi1-free", "--no-rrd")
    assert code == 2 and err.count("\n") == 1
    assert "manifest.json: config: the manifest's config changed since the study was run" in err
