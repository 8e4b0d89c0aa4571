"""The CARLA log importer on the committed raw sample of the authors' logs (real format, thinned):
road sequences against the authors' route tables, their logged belief replayed road by road, the
authors' statistics rules against literal re-runs of their loops, and malformed inputs."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.cli import run_cli
from trustroute.analysis.carla_study.analysis import (
    authors_belief_replay,
    authors_point_rule,
    authors_segment_rule,
    with_real_columns,
)
from trustroute.analysis.carla_study.log_import import LOG_TRUNCATED, import_carla_logs, log_ending
from trustroute.analysis.carla_study.log_schema import read_real_table
from trustroute.analysis.carla_study.town01 import load_carla_tables
from trustroute.analysis.formatting import number_text
from trustroute.core.dataset import read_episodes, read_roads
from trustroute.participants.driver_model import load_driver_model

RAW = Path(__file__).resolve().parents[3] / "analysis" / "data" / "real_study" / "raw"
SAMPLE = "trust_level_record_driver_4_trial_1_if_baseline_0.csv"


@pytest.fixture(scope="module")
def imported(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("carla") / "study"
    import_carla_logs(RAW, out)
    return out


def _tables(study: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    episodes, roads = with_real_columns(study, read_episodes(study), read_roads(study))
    return episodes, roads


def _roads(study: Path) -> pd.DataFrame:
    return _tables(study)[1]


def _episodes(study: Path) -> pd.DataFrame:
    return _tables(study)[0]


def test_free_episodes_drive_the_authors_preset_baseline_routes(imported):
    tables = load_carla_tables()
    roads, episodes = _roads(imported), _episodes(imported)
    checked = 0
    for episode in episodes[episodes["condition"] == "free"].itertuples():
        states = list(roads[roads["episode_id"] == episode.episode_id].sort_values("index")["authors_state"])
        preset = [tables.trials[episode.trial]["start"], *tables.baseline_routes[episode.trial]]
        if episode.episode_id == "d03-t2-free":
            # this participant's car left the preset route at B (B-G instead of B-C) and came
            # back to it at A; every road is still a legal move of the town
            assert states[:4] == preset[:4] and states[-5:] == preset[-5:]
        else:
            assert states == preset
            checked += 1
    assert checked == 2


def test_every_road_sequence_is_a_walk_of_the_authors_state_graph(imported):
    tables = load_carla_tables()
    roads = _roads(imported)
    for _, group in roads.groupby("episode_id"):
        states = list(group.sort_values("index")["authors_state"])
        for a, b in zip(states, states[1:], strict=False):
            assert b in tables.successors(a) or a == b


def test_aware_routes_end_as_the_authors_shortest_route_tables_say_when_the_goal_is_near(imported):
    # the last road of a finished aware episode enters the trial's goal junction
    tables = load_carla_tables()
    roads, episodes = _roads(imported), _episodes(imported)
    for episode in episodes[episodes["condition"] == "aware"].itertuples():
        last = roads[roads["episode_id"] == episode.episode_id].sort_values("index").iloc[-1]
        assert last["directed_road"].endswith(tables.trials[episode.trial]["goal"])
        assert tables.shortest_routes[episode.trial][last["authors_state"]] == []


def test_replaying_the_authors_belief_update_reproduces_the_logged_belief_road_by_road(imported):
    tables, driver = load_carla_tables(), load_driver_model(None)
    roads, episodes = _roads(imported), _episodes(imported)
    compared = 0
    for episode in episodes[episodes["condition"] == "aware"].itertuples():
        group = roads[roads["episode_id"] == episode.episode_id].sort_values("index")
        replay = authors_belief_replay(group, episode.trial, tables, driver)
        logged = np.stack(group["logged_belief"].to_numpy())
        np.testing.assert_allclose(replay, logged, atol=1e-12)
        compared += len(group)
    assert compared >= 15
    # and the replay is not vacuous: the logged belief moves away from uniform
    assert np.abs(logged - 1 / 7).max() > 0.1


def test_takeovers_and_reports_come_from_the_ticks(imported):
    raw = pd.read_csv(RAW / SAMPLE, index_col=0)
    roads = _roads(imported)
    group = roads[roads["episode_id"] == "d04-t1-aware"].sort_values("index")
    manual = raw.index[raw["if_autopilot"].astype(str) == "False"].to_numpy()
    for row in group.itertuples():
        if row.index == 0:
            assert pd.isna(row.takeover)  # the start road has no observation
        else:
            assert row.takeover == bool(((manual >= row.tick_first) & (manual <= row.tick_last)).any())
        assert row.reported_trust == raw.loc[int(row.tick_last), "trust_level"]


def _authors_point_loop(frame: pd.DataFrame) -> tuple[bool, float, float]:
    """statistic_test_point_based.py's loop, literally, on one file."""
    num = num_total = num_satisfy = 0
    trust = 0
    for k in range(frame.shape[0]):
        if str(frame.iloc[k, 3]) == "True":
            num_total += 1
            trust += frame.iloc[k, 1]
            if frame.iloc[k, 1] >= 2:
                num_satisfy += 1
        else:
            num += 1
    return num_satisfy / num_total >= 0.99, trust / num_total, num / (num + num_total)


def _authors_segment_loop(frame: pd.DataFrame) -> float:
    """statistic_test_segment_based.py's average segment trust, literally, on one file."""
    road_last = [int(frame.iloc[1, 2].split(",")[-2].strip())]
    totals, sums = [1], [frame.iloc[1, 1]]
    for k in range(2, frame.shape[0]):
        if str(frame.iloc[k, 3]) == "True":
            road = int(frame.iloc[k, 2].split(",")[-2].strip())
            if road_last[-1] == road:
                totals[-1] += 1
                sums[-1] += frame.iloc[k, 1]
            else:
                road_last.append(road)
                totals.append(1)
                sums.append(frame.iloc[k, 1])
    closed = [s / t for s, t in zip(sums[:-1], totals[:-1], strict=True)]
    return sum(closed) / len(closed)


def test_authors_rules_match_literal_runs_of_their_loops(imported):
    ticks = read_real_table(imported, "ticks")
    point = authors_point_rule(ticks).set_index("episode_id")
    segment = authors_segment_rule(ticks).set_index("episode_id")
    episodes = _episodes(imported).set_index("episode_id")
    for episode_id, row in episodes.iterrows():
        frame = pd.read_csv(RAW / Path(row["source_file"]).name)
        satisfied, average, takeover = _authors_point_loop(frame)
        assert bool(point.loc[episode_id, "authors_satisfied"]) == satisfied
        assert point.loc[episode_id, "authors_average_trust"] == pytest.approx(average, abs=1e-12)
        assert point.loc[episode_id, "authors_takeover_probability"] == pytest.approx(takeover, abs=1e-12)
        assert segment.loc[episode_id, "authors_segment_trust"] == pytest.approx(
            _authors_segment_loop(frame), abs=1e-12
        )


def test_warm_up_and_missing_sessions_are_recorded_not_dropped(imported):
    import json

    manifest = json.loads((imported / "manifest.json").read_text())
    inventory = manifest["real_study"]["inventory"]
    warmups = [e for e in inventory if e["role"] == "warmup"]
    assert [e["file"] for e in warmups] == ["trust_level_record_driver_4_trial_3_if_baseline_0.csv"]
    assert "driver 4 trial 2 aware" in manifest["real_study"]["missing_sessions"]


def test_a_missing_warm_up_is_named_as_the_warm_up_not_as_a_trial(tmp_path, capsys):
    """Drivers 3 and 16 of the raw sample have no warm-up log: the import's summary, its --json and
    the manifest name each as the driver's warm-up (its file's trial 3 is no trial of the study),
    as does the packaged release's manifest for drivers 8, 24 and 26."""
    import json

    code, text, err = run_cli(capsys, "import", "carla-logs", str(RAW), "--out", str(tmp_path / "study"),
                              "--quiet")
    assert code == 0, err
    listed = text.split("missing sessions: ")[1].splitlines()[0].split(", ")
    manifest = json.loads((tmp_path / "study" / "manifest.json").read_text())["real_study"]
    assert listed == manifest["missing_sessions"]
    assert [s for s in listed if "warm-up" in s] == ["driver 3 warm-up", "driver 16 warm-up"]
    assert not [s for s in listed if "trial 3" in s]
    code, text, err = run_cli(capsys, "import", "carla-logs", str(RAW), "--out", str(tmp_path / "again"),
                              "--json")
    assert code == 0, err
    assert json.loads(text)["missing_sessions"] == listed
    packaged = json.loads((STUDY / "manifest.json").read_text())["real_study"]["missing_sessions"]
    assert sorted(s for s in packaged if "warm-up" in s) == ["driver 24 warm-up", "driver 26 warm-up",
                                                             "driver 8 warm-up"]
    assert len(packaged) == 10 and all(s.endswith("trial 2 aware") for s in packaged if "warm-up" not in s)


SESSION_POSITIONS = {"t1-aware": 0, "t1-free": 1, "t2-aware": 2, "t2-free": 3}   # docs/real_study.md


def test_positions_are_the_study_sessions_from_0(imported):
    """An episode's position is its place among the four study sessions, 0-based as in every study
    (docs/dataset.md); the warm-up driven before them is no episode. The committed import agrees."""
    for study in (imported, STUDY):
        episodes = read_episodes(study)
        expected = [SESSION_POSITIONS[e[4:]] for e in episodes["episode_id"]]
        assert episodes["position"].tolist() == expected, study


def test_analyze_reads_the_imported_study(imported, capsys):
    import json

    code, out, err = run_cli(capsys, "analyze", str(imported), "--json", "--no-report")
    assert code == 0, err
    payload = json.loads(out)
    per = {row["episode_id"]: row for row in payload["real_study"]["per_episode"]}
    assert set(per) == set(_episodes(imported)["episode_id"])
    assert all(isinstance(row["satisfied_bayes"], bool) for row in per.values())
    assert {m["figure"] for m in payload["real_study"]["paper_matches"]} >= {
        "satisfaction rate (aware)",
        "mean trust (free)",
    }


def test_one_log_file_imports_as_a_study_of_its_episode(tmp_path, capsys):
    import json

    out = tmp_path / "one"
    code, _, err = run_cli(capsys, "import", "carla-logs", str(RAW / SAMPLE), "--out", str(out), "--quiet")
    assert code == 0, err
    real = json.loads((out / "manifest.json").read_text())["real_study"]
    assert [(entry["file"], entry["status"]) for entry in real["inventory"]] == [(SAMPLE, "imported")]
    assert list(_episodes(out)["episode_id"]) == ["d04-t1-aware"]
    code, text, err = run_cli(capsys, "analyze", str(out), "--json", "--no-report")
    assert code == 0, err
    assert [row["episode_id"] for row in json.loads(text)["real_study"]["per_episode"]] == ["d04-t1-aware"]
    code, text, _ = run_cli(capsys, "import", "carla-logs", "--help")
    assert "or one such CSV (a study of that one episode)" in " ".join(text.split())
    # imported again in place, as an earlier import of the same logs
    code, _, err = run_cli(capsys, "import", "carla-logs", str(RAW / SAMPLE), "--out", str(out), "--quiet")
    assert code == 0, err


def test_a_log_cut_at_a_line_boundary_is_named_as_truncated(imported, tmp_path, capsys):
    """A log cut mid-drive at a newline holds only valid cells: the import names it as truncated (its
    summary, --json and log_end); the complete packaged logs are not."""
    import json

    folder = tmp_path / "logs"
    folder.mkdir()
    lines = (RAW / SAMPLE).read_text().splitlines(keepends=True)
    (folder / SAMPLE).write_text("".join(lines[: len(lines) // 2]))
    def run(source: Path, out: str, *options: str) -> str:
        code, text, err = run_cli(capsys, "import", "carla-logs", str(source), "--out", str(tmp_path / out),
                                  *options)
        assert code == 0, err
        return text

    text = run(folder, "a", "--json")
    assert json.loads(text)["truncated_logs"] == [SAMPLE]
    assert list(read_real_table(tmp_path / "a", "real_episodes")["log_end"]) == [LOG_TRUNCATED]
    (line,) = [line for line in run(folder, "b").splitlines() if "truncated" in line]
    assert line.startswith("1 log truncated (the drive ended on a road before the route's end") and \
        line.endswith(f": {SAMPLE}"), line
    assert json.loads(run(RAW, "c", "--json"))["truncated_logs"] == []
    assert LOG_TRUNCATED not in set(read_real_table(imported, "real_episodes")["log_end"])


def test_a_malformed_single_log_is_named_by_its_file(tmp_path, capsys):
    folder = _bad_copy(tmp_path, SAMPLE, _ticks(lambda t: _set(t, 40, "x")))
    err = _one_line_error(capsys, folder / SAMPLE, tmp_path)
    assert err.startswith(f"error: {SAMPLE}: line 42, column tick "), err   # row 40 after the header


# -- malformed inputs: one line, exit 2 ---------------------------------------------------
def _bad_copy(tmp_path: Path, name: str, edit) -> Path:
    folder = tmp_path / "logs"
    folder.mkdir()
    frame = pd.read_csv(RAW / SAMPLE, index_col=0)
    edit(frame).to_csv(folder / name)
    return folder


def _one_line_error(capsys, folder: Path, tmp_path: Path) -> str:
    code, out, err = run_cli(capsys, "import", "carla-logs", str(folder), "--out", str(tmp_path / "out"))
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "out" / "manifest.json").exists()
    return err


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_every_real_study_value_in_the_terminal_stands_beside_its_reading_and_subset(imported, capsys):
    """At the terminal's 120 columns each value row keeps its figure and reading on its own line,
    under a heading naming its subset: a row of numbers that names neither cannot be read."""
    import json
    import re

    code, out, err = run_cli(capsys, "analyze", str(imported), "--json", "--no-report")
    assert code == 0, err
    figures = json.loads(out)["real_study"]["figures"]
    code, out, err = run_cli(capsys, "analyze", str(imported), "--no-report")
    assert code == 0, err
    section = out[out.index("Real CARLA study"):]
    assert max(len(line) for line in section.splitlines()) <= 120
    blocks = {block.splitlines()[0]: block for block in section.split("\n\n") if block.startswith("subset: ")}
    for row in figures:
        aware, free = (re.escape(number_text(row[c], 4)) for c in ("aware", "free"))
        values = re.compile(rf"  {aware} +{free} ")
        block = blocks[f"subset: {row['subset']}"]
        assert any(line.startswith(row["figure"]) and row["reading"][:30] in line and values.search(line)
                   for line in block.splitlines()), (row, block)


def test_replaying_an_imported_episode_says_there_is_no_config_to_rerun(imported, capsys):
    code, out, err = run_cli(capsys, "replay", str(imported), "d04-t1-aware")
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err
    assert "imported from CARLA logs has no study config" in err, err
    assert f"trustroute analyze {imported}" in err, err


def test_another_study_in_out_is_refused_and_left_as_it_was(imported, tmp_path, capsys):
    simulated = tmp_path / "simulated"
    (simulated / "parts").mkdir(parents=True)
    (simulated / "parts" / "p00000-phi1-free.zip").write_bytes(b"a part")
    (simulated / "manifest.json").write_text('{"study": "mine", "engine": "model"}')
    other_logs = tmp_path / "other"
    other_logs.mkdir()
    shutil.copy(RAW / SAMPLE, other_logs / SAMPLE)
    earlier = tmp_path / "earlier"
    shutil.copytree(imported, earlier)
    for source, out in ((RAW, simulated), (other_logs, earlier)):
        before = _files(out)
        code, _, err = run_cli(capsys, "import", "carla-logs", str(source), "--out", str(out), "--quiet")
        assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
        assert f"{out}: --out: holds a study (manifest.json" in err and "not an import of these logs" in err
        assert _files(out) == before
    # the same logs again into their own earlier import: imported again in place
    code, _, err = run_cli(capsys, "import", "carla-logs", str(RAW), "--out", str(earlier), "--quiet")
    assert code == 0, err
    assert read_episodes(earlier).equals(read_episodes(imported))


def test_a_folder_of_other_files_is_refused_and_left_as_it_was(tmp_path, capsys):
    """An import writes a study's tables: into a new or empty folder, or its own earlier import,
    never among a person's files (the rule of a study's --out)."""
    home = tmp_path / "home"
    (home / "photos").mkdir(parents=True)
    (home / "notes.txt").write_text("mine")
    before = _files(home)
    code, _, err = run_cli(capsys, "import", "carla-logs", str(RAW), "--out", str(home), "--quiet")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert f"{home}: --out: the folder holds files that are not a study's (notes.txt, photos)" in err
    assert sorted(p.name for p in home.iterdir()) == ["notes.txt", "photos"] and _files(home) == before


def test_missing_column_is_one_line(tmp_path, capsys):
    folder = _bad_copy(tmp_path, SAMPLE, lambda f: f.drop(columns=["if_autopilot"]))
    assert "if_autopilot" in _one_line_error(capsys, folder, tmp_path)


def test_unknown_trial_is_one_line(tmp_path, capsys):
    folder = _bad_copy(tmp_path, SAMPLE.replace("trial_1", "trial_7"), lambda f: f)
    assert "unknown trial 7" in _one_line_error(capsys, folder, tmp_path)


def test_location_off_every_road_is_one_line(tmp_path, capsys):
    def move(frame: pd.DataFrame) -> pd.DataFrame:
        frame.iloc[40, frame.columns.get_loc("location")] = "(900.0, -700.0, 3, 1)"
        return frame

    folder = _bad_copy(tmp_path, SAMPLE, move)
    err = _one_line_error(capsys, folder, tmp_path)
    assert "maps to no road" in err and f"{SAMPLE}: line 42, column location: (900.0, -700.0)" in err


def _cell(column: str, value: object, row: int = 40):
    def edit(frame: pd.DataFrame) -> pd.DataFrame:
        frame = frame.astype({column: object})
        frame.iloc[row, frame.columns.get_loc(column)] = value
        return frame

    return edit


def _ticks(change):
    """An edit of the tick index (the unnamed first column)."""
    def edit(frame: pd.DataFrame) -> pd.DataFrame:
        ticks = frame.index.to_numpy().astype(object)
        change(ticks)
        frame.index = ticks
        return frame

    return edit


def _set(ticks, row, value):
    ticks[row] = value


def _swap(ticks, row):
    ticks[row], ticks[row + 1] = ticks[row + 1], ticks[row]


MALFORMED_CELLS = {
    "tick_not_a_number": (_ticks(lambda t: _set(t, 40, "x")), "line 42, column tick", "not a tick index"),
    "tick_repeated": (_ticks(lambda t: _set(t, 41, t[40])), "line 43, column tick", "does not follow"),
    "ticks_reversed": (_ticks(lambda t: _swap(t, 40)), "line 43, column tick", "does not follow"),
    "location_of_two_numbers": (_cell("location", "(67.1, 1.9)"), "line 42, column location", "2 entries"),
    "location_nan": (_cell("location", "(nan, 1.9, 3, 1)"), "line 42, column location", "not 4 numbers"),
    "location_inf": (_cell("location", "(inf, 1.9, 3, 1)"), "line 42, column location", "not finite"),
    "location_fractional_road_id": (_cell("location", "(67.1, 1.9, 3.5, 1)"), "line 42, column location",
                                    "whole road"),
    "trust_between_levels": (_cell("trust_level", 4.5), "line 42, column trust_level", "not a level 1..7"),
    "belief_of_two_levels": (_cell("trust_belief", "(0.5, 0.5)"), "line 42, column trust_belief",
                             "2 entries, not 7"),
    "belief_with_negative_entries": (_cell("trust_belief", "(-0.5, 0.5, 0.5, 0.5, 0, 0, 0)"),
                                     "line 42, column trust_belief", "outside [0, 1]"),
    "belief_not_summing_to_one": (_cell("trust_belief", "(0.5, 0.5, 0.5, 0, 0, 0, 0)"),
                                  "line 42, column trust_belief", "sum to 1.5"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED_CELLS))
def test_a_malformed_cell_is_one_line_naming_its_line_and_column(case, tmp_path, capsys):
    """The line is the file's, as an editor numbers it: the header is line 1, row 40 is line 42."""
    edit, place, problem = MALFORMED_CELLS[case]
    folder = _bad_copy(tmp_path, SAMPLE, edit)
    err = _one_line_error(capsys, folder, tmp_path)
    assert f"{SAMPLE}: {place}" in err and problem in err, err
    assert not (tmp_path / "out").exists()
    line = int(place.split()[1].rstrip(","))
    edited = pd.read_csv(folder / SAMPLE, index_col=0)
    row = line - 2
    assert (folder / SAMPLE).read_text().splitlines()[line - 1].startswith(f"{edited.index[row]},"), line


def test_not_a_log_folder_is_one_line(tmp_path, capsys):
    (tmp_path / "logs").mkdir()
    err = _one_line_error(capsys, tmp_path / "logs", tmp_path)
    assert "no trust_level_record" in err
    err = _one_line_error(capsys, tmp_path / "no-logs", tmp_path)
    assert "no-logs: no such file or directory (fix: pass a checkout" in err and "one of their CSVs" in err
    # a single file that is not a log: said of the file, with the fix every other refusal gives
    other = tmp_path / "notes.csv"
    other.write_text("trust_level\n1\n")
    err = _one_line_error(capsys, other, tmp_path)
    assert err.startswith(f"error: {other}: not a trust_level_record_driver_*_trial_*_if_baseline_*.csv file "
                          "(fix: pass a checkout of the authors' repository, a folder of their CSVs or one "
                          "of their CSVs)"), err


def test_a_log_is_found_wherever_the_folder_or_file_given_lies(tmp_path, capsys):
    """Only statistic_test/ under the folder given holds the copies read as subsets: a log passed
    alone, or a folder that itself lies under a statistic_test/ folder, is imported."""
    import json

    inside = tmp_path / "statistic_test" / "trust_aware"
    inside.mkdir(parents=True)
    (inside / SAMPLE).write_bytes((RAW / SAMPLE).read_bytes())
    for source in (inside / SAMPLE, inside):
        out = tmp_path / f"out-{source.name}"
        code, _, err = run_cli(capsys, "import", "carla-logs", str(source), "--out", str(out), "--quiet")
        assert code == 0, err
        inventory = json.loads((out / "manifest.json").read_text())["real_study"]["inventory"]
        assert [(entry["file"], entry["status"]) for entry in inventory] == [(SAMPLE, "imported")]


def test_sample_files_are_unchanged_copies_of_the_authors_format():
    frame = pd.read_csv(RAW / SAMPLE)
    assert list(frame.columns) == ["Unnamed: 0", "trust_level", "location", "if_autopilot", "trust_belief"]


# -- the committed conversion of the whole release ----------------------------------------
STUDY = RAW.parent / "study"


def test_committed_study_replays_the_logged_belief_on_every_aware_road():
    tables, driver = load_carla_tables(), load_driver_model(None)
    roads, episodes = _roads(STUDY), _episodes(STUDY)
    aware = episodes[episodes["condition"] == "aware"]
    assert len(aware) == 35  # 21 trial-1 runs and the 14 trial-2 runs whose files exist
    for episode in aware.itertuples():
        group = roads[roads["episode_id"] == episode.episode_id].sort_values("index")
        replay = authors_belief_replay(group, episode.trial, tables, driver)
        np.testing.assert_allclose(replay, np.stack(group["logged_belief"].to_numpy()), atol=1e-12)


def test_committed_study_free_runs_follow_the_preset_routes_except_two_recorded_detours():
    tables = load_carla_tables()
    roads, episodes = _roads(STUDY), _episodes(STUDY)
    detours = []
    for episode in episodes[episodes["condition"] == "free"].itertuples():
        states = list(roads[roads["episode_id"] == episode.episode_id].sort_values("index")["authors_state"])
        if states != [tables.trials[episode.trial]["start"], *tables.baseline_routes[episode.trial]]:
            detours.append(episode.episode_id)
    assert detours == ["d03-t2-free", "d06-t1-free"]  # docs/real_study.md, "Mapping decisions"


def test_no_log_of_the_release_ends_truncated():
    """Every committed log ends as the authors' script ends a run (their last row is the arrival at
    the goal junction, or the goal was reached before the run was stopped): the ending rule, run
    on each episode's roads, flags none and gives the log_end the import wrote."""
    tables = load_carla_tables()
    roads, episodes = _roads(STUDY), _episodes(STUDY)
    endings = {}
    for episode in episodes.itertuples():
        group = roads[roads["episode_id"] == episode.episode_id].sort_values("index")
        endings[episode.episode_id] = log_ending(group, tables.trials[episode.trial]["goal"])
        assert endings[episode.episode_id] == (episode.end_reason, episode.log_end), episode.episode_id
    assert len(endings) == 77 and LOG_TRUNCATED not in {end for _, end in endings.values()}


@pytest.mark.slow
def test_committed_study_is_analysed_with_every_file_accounted_for(tmp_path, capsys):
    import json

    study = tmp_path / "study"
    shutil.copytree(STUDY, study)
    code, out, err = run_cli(capsys, "analyze", str(study), "--json", "--report")
    assert code == 0, err
    payload = json.loads(out)
    real = payload["real_study"]
    assert payload["paths"]["real_study_json"] == str(study / "real_study.json")
    assert len(real["participants"]) == 21
    assert len(real["per_episode"]) == 77
    statuses = {e["status"] for e in real["excluded_files"]}
    assert any("warm-up" in s for s in statuses) and any("pilot" in s for s in statuses)
    assert len(real["missing_sessions"]) == 10
    assert (study / "real_study.json").exists()
    assert "Real CARLA study" in (study / "report.md").read_text()
    tests = real["authors_paired_tests"]
    assert {t["quantity"] for t in tests} >= {"average trust (autopilot ticks)", "LDTL satisfied (0/1)"}
    assert all(t["pairs"] in (20, 21) for t in tests)


def test_the_excluded_files_line_keeps_each_count_beside_its_reason():
    """Each status is a phrase with a comma of its own ("pilot/test driver, excluded"): the counts are
    kept apart by semicolons, so that every count reads with its reason."""
    from trustroute.analysis.carla_study.analysis import RealStudyAnalysis, format_real_study

    inventory = [{"status": "pilot/test driver, excluded"}] * 2 + [{"status": "warm-up trial, not analysed"}]
    analysis = RealStudyAnalysis(pd.DataFrame(), [], [], {"real_study": {"inventory": inventory}})
    lines = format_real_study(analysis, width=None).splitlines()
    assert lines[-1] == "excluded files: 2 pilot/test driver, excluded; 1 warm-up trial, not analysed"


def test_an_authors_t_test_that_cannot_be_computed_says_why():
    """One pair (a single driver's logs) gives no t-test: the line says so, in the singular, rather
    than 't = -, p = - (1 pairs)'."""
    from trustroute.analysis.carla_study.analysis import (
        RealStudyAnalysis,
        authors_paired_tests,
        format_real_study,
    )

    per = pd.DataFrame({"participant": [4, 4], "trial": [1, 1], "condition": ["aware", "free"],
                        "in_authors_subset": [False, False], "fraction_trust_at_least_2": [1.0, 0.9],
                        "authors_average_trust": [5.0, 4.0], "authors_takeover_probability": [0.0, 0.1],
                        "authors_satisfied": [1.0, 0.0]})
    tests = authors_paired_tests(per)
    analysis = RealStudyAnalysis(per, [], [], {"real_study": {}}, tests)
    lines = [line for line in format_real_study(analysis, width=None).splitlines() if "t-test" in line]
    assert len(lines) == 4
    assert all(line.endswith("t = -, p = - (fewer than 2 pairs; 1 pair)") for line in lines), lines
