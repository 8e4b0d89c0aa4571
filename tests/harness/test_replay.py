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
        assert replay.warnings == ()


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


def test_a_recording_in_a_package_is_refused_before_the_replay(sumo_study, tmp_path, capsys):
    """A package (its config and tables folder) is published read-only: a recording to write in
    one is one line naming it, before the episode runs, and nothing is written there."""
    package = tmp_path / "package"
    (package / "tables").mkdir(parents=True)
    (package / "study_config.json").write_text("{}")
    code, out, err = run_cli(capsys, "replay", str(sumo_study), "p00000-phi1-aware", "--rrd",
                             str(package / "replay.rrd"))
    assert code == 2 and out == "" and err.count("\n") == 1 and f"lies in the package {package}" in err
    assert sorted(p.name for p in package.rglob("*")) == ["study_config.json", "tables"]


def _tamper_trust(study, episode_id, index):
    """Change the logged trust after road `index` of `episode_id` by one level."""
    _tamper(study, "roads", episode_id, "trust_after", lambda t: t + 1 if t < 7 else t - 1, index)


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


# Every column of the kinematics and incidents tables, a float changed by 1e-9 or a value set where
# the log has none: each is named by its table, the episode, its row and its column.
@pytest.mark.slow
@pytest.mark.parametrize(("table", "column", "change", "row"), [
    ("kinematics", "speed", lambda v: v + 1e-9, 40),
    ("kinematics", "lane", lambda v: f"{v}x", 40),
    ("kinematics", "mode", lambda v: "manual" if v == "auto" else "auto", 0),
    ("incidents", "time_lost", lambda v: v + 1e-9, 2),
    ("incidents", "scene", lambda v: f"{v} edited", 2),
    ("incidents", "takeover_reaction", lambda v: 0.5 if pd.isna(v) or v != 0.5 else 0.25, 2),
])
def test_replay_compares_every_row_of_kinematics_and_incidents(sumo_study, tmp_path, capsys, table, column,
                                                               change, row):
    study = _copy(sumo_study, tmp_path)
    _tamper(study, table, "p00000-phi2-free", column, change, row)
    code, out, err = run_cli(capsys, "replay", str(study), "p00000-phi2-free", "--no-rrd")
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err
    assert (f"p00000-phi2-free: the replay does not reproduce the log: {table}.parquet row {row} {column}: "
            "logged ") in err, err


@pytest.mark.slow
@pytest.mark.parametrize(("table", "row"), [("kinematics", -1), ("incidents", 1)])
def test_replay_compares_the_rows_of_kinematics_and_incidents_one_by_one(sumo_study, tmp_path, capsys,
                                                                         table, row):
    study = _copy(sumo_study, tmp_path)
    logged = pd.read_parquet(study / f"{table}.parquet")
    rows = int((logged["episode_id"] == "p00000-phi2-free").sum())
    _tamper(study, table, "p00000-phi2-free", "", None, row)   # one row deleted
    code, out, err = run_cli(capsys, "replay", str(study), "p00000-phi2-free", "--no-rrd")
    first = row % rows
    assert code == 2 and out == "" and err.count("\n") == 1
    assert (f"{table}.parquet: the replay has {rows} rows of the episode, the log {rows - 1} "
            f"(first difference at row {first})") in err, err


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


def _tamper(study, table, episode_id, column, change, row):
    """Change `column` of the `row`-th row of `episode_id` (in the file's order: a road's row is
    its index) in the study table `table` (a key of dataset.TABLES) by `change` (old -> new value);
    `change=None` deletes the row."""
    from trustroute.core import dataset

    file_name, schema = dataset.TABLES[table]
    frame = dataset.frame_from_table(dataset.read_study_table(study, table))
    at = frame.index[frame["episode_id"] == episode_id][row]
    if change is None:
        frame = frame.drop(index=at)
    else:
        frame.at[at, column] = change(frame.at[at, column])
    dataset.write_table(dataset.table_from_frame(frame, schema), study / file_name)


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
    _tamper(study, table, "p00001-phi1-free", column, change, 0 if table == "episodes" else 3)
    code, out, err = run_cli(capsys, "replay", str(study), "p00001-phi1-free", "--no-rrd")
    where = f"road 3 {column}" if table == "roads" else f"episodes.parquet {column}"
    assert code == 2 and out == "" and f"does not reproduce the log: {where}" in err, err


def test_replay_ignores_the_wall_clock(model_study, tmp_path, capsys):
    study = _copy(model_study, tmp_path)
    _tamper(study, "episodes", "p00001-phi1-free", "wall_seconds", lambda v: v + 99.0, 0)
    code, out, err = run_cli(capsys, "replay", str(study), "p00001-phi1-free", "--no-rrd")
    assert code == 0 and "replay reproduces the log" in out, err


def test_replay_warns_of_a_manifest_without_a_config_hash(model_study, tmp_path, capsys):
    study = _copy(model_study, tmp_path)
    code, out, err = run_cli(capsys, "replay", str(study), "p00001-phi1-free", "--no-rrd", "--json")
    assert code == 0 and json.loads(out)["warnings"] == [] and "warning" not in err
    manifest = json.loads((study / "manifest.json").read_text())
    del manifest["inputs"]["config_sha256"]   # as a manifest written before config hashes were recorded
    (study / "manifest.json").write_text(json.dumps(manifest))
    code, out, err = run_cli(capsys, "replay", str(study), "p00001-phi1-free", "--no-rrd", "--json")
    warning = f"{study / 'manifest.json'}: inputs.config_sha256: absent"
    assert code == 0 and err.count("\n") == 1 and err.startswith(f"warning: {warning}"), err
    assert json.loads(out)["warnings"] == [err.removeprefix("warning: ").rstrip("\n")]
    # an edited config is then found only by the replay's difference: the warning comes first
    manifest["config"]["seed"] = 2
    (study / "manifest.json").write_text(json.dumps(manifest))
    code, out, err = run_cli(capsys, "replay", str(study), "p00001-phi1-free", "--no-rrd")
    lines = err.splitlines()
    assert code == 2 and out == "" and len(lines) == 2, err
    assert lines[0].startswith(f"warning: {warning}") and "does not reproduce the log" in lines[1]


def test_replay_refuses_a_changed_config_in_the_manifest(model_study, tmp_path, capsys):
    study = _copy(model_study, tmp_path)
    manifest = json.loads((study / "manifest.json").read_text())
    manifest["config"]["seed"] = 2
    (study / "manifest.json").write_text(json.dumps(manifest))
    code, _, err = run_cli(capsys, "replay", str(study), "p00001-phi1-free", "--no-rrd")
    assert code == 2 and err.count("\n") == 1
    assert "manifest.json: config: the manifest's config changed since the study was run" in err
