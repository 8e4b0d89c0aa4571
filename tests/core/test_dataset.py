"""The dataset definition: schemas are enforced on write and on read, missing values are nulls."""

from __future__ import annotations

import json

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from tests.study_tables import duplicate_row, set_values, study_copy
from trustroute.core import dataset
from trustroute.core.errors import InputError


def test_consolidated_study_matches_every_schema(model_study):
    for name, (file_name, schema) in dataset.TABLES.items():
        path = model_study / file_name
        if not path.exists():
            assert name in ("kinematics", "incidents", "attempts", "questionnaires")  # SUMO; live only
            continue
        table = pq.read_table(path)
        dataset.check_table(table.replace_schema_metadata(None), schema, file_name)
    manifest = dataset.read_manifest(model_study)
    assert tuple(manifest) == dataset.MANIFEST_KEYS
    assert manifest["files"] == {"episodes": dataset.EPISODES_FILE, "roads": dataset.ROADS_FILE}


def test_missing_values_are_nulls(model_study):
    roads = dataset.read_roads(model_study)
    start = roads[roads["index"] == 0]
    assert (start["incident"] == "none").all()
    assert start["takeover"].isna().all() and start["performance"].isna().all()
    assert start["reported_trust"].isna().all()
    assert roads["reported_trust"].dtype == "Int64" and roads["takeover"].dtype == "boolean"
    last = roads.groupby("episode_id")["index"].transform("max") == roads["index"]
    assert roads.loc[last, "action"].isna().all() and roads.loc[~last, "action"].notna().all()
    assert (roads["reported_trust"].dropna() >= 1).all()  # never -1 for "no report"
    assert roads["sim_time_in"].isna().all()  # the model engine has no simulator clock
    episodes = dataset.read_episodes(model_study)
    assert episodes["sim_seconds"].isna().all()
    assert tuple(episodes.columns) == tuple(dataset.EPISODES_SCHEMA.names)


def test_reader_rejects_another_schema(tmp_path, model_study):
    roads = pq.read_table(model_study / dataset.ROADS_FILE)
    pq.write_table(roads.drop_columns(["dfa_state"]), tmp_path / dataset.ROADS_FILE)
    with pytest.raises(InputError, match="roads.parquet: schema: .*columns"):
        dataset.read_roads(tmp_path)
    retyped = roads.set_column(roads.schema.get_field_index("index"), "index",
                               roads.column("index").cast(pa.float64()))
    pq.write_table(retyped, tmp_path / dataset.ROADS_FILE)
    with pytest.raises(InputError, match="'index' is double, expected int64"):
        dataset.read_roads(tmp_path)
    with pytest.raises(InputError, match="no such dataset file"):
        dataset.read_episodes(tmp_path)


def test_nulls_are_refused_where_the_schema_forbids_them():
    frame = pd.DataFrame({"episode_id": ["e"], "time": [None], "x": [0.0], "y": [0.0], "speed": [1.0],
                          "lane": ["l"], "mode": ["auto"]})
    with pytest.raises(dataset.SchemaError, match="time"):
        dataset.table_from_frame(frame, dataset.KINEMATICS_SCHEMA)


def test_manifest_without_a_key_is_refused(tmp_path, model_study):
    manifest = json.loads((model_study / dataset.MANIFEST_FILE).read_text())
    del manifest["seeds"]
    (tmp_path / dataset.MANIFEST_FILE).write_text(json.dumps(manifest))
    with pytest.raises(InputError, match="seeds: missing manifest key"):
        dataset.read_manifest(tmp_path)


def test_rows_and_columns_give_the_same_table():
    """table_from_rows (one struct conversion) and table_from_columns agree, NaN and None are nulls
    in both, and a null in a non-null field is a SchemaError in both."""
    schema = dataset.INCIDENTS_SCHEMA
    nan = float("nan")
    base = {name: None for name in schema.names}
    base.update(episode_id="e1", index=1, directed_road="A-B", incident="truck", takeover=False,
                performance="succ", min_ttc=float("inf"), max_deceleration=2.5, collided=False,
                min_head_on_ttc=1.75, min_pedestrian_distance=float("inf"), time_lost=0.5,
                injected_time=3.0, x=nan, y=nan)
    rows = [base, {**base, "index": 2, "takeover": True, "takeover_start": 7.5, "in_view_time": nan}]
    by_rows = dataset.table_from_rows(rows, schema)
    by_columns = dataset.table_from_columns({name: [row[name] for row in rows] for name in schema.names},
                                            schema)
    assert by_rows.schema.equals(schema) and by_rows.equals(by_columns)
    assert by_rows.column("x").null_count == 2 and by_rows.column("takeover_start").to_pylist() == [None, 7.5]
    for build in (dataset.table_from_rows, lambda r, s: dataset.table_from_columns(
            {name: [row[name] for row in r] for name in s.names}, s)):
        with pytest.raises(dataset.SchemaError, match="time_lost"):
            build([{**base, "time_lost": nan}], schema)
        with pytest.raises(dataset.SchemaError, match="episode_id"):
            build([{**base, "episode_id": None}], schema)


def test_check_table_fast_path_still_finds_nulls_and_casts():
    """A table of the schema itself is returned as it is unless a non-null field has nulls; one whose
    nullability differs is cast (the slow path), as before."""
    schema = dataset.KINEMATICS_SCHEMA
    columns = {"episode_id": ["e"], "time": [0.5], "x": [1.0], "y": [2.0], "speed": [3.0], "lane": ["A-B_1"],
               "mode": ["auto"]}
    table = dataset.table_from_columns(columns, schema)
    assert dataset.check_table(table, schema) is table
    loose = pa.table({name: pa.array(values) for name, values in columns.items()})
    assert dataset.check_table(loose, schema).schema.equals(schema)
    holed = pa.Table.from_arrays([pa.array([None], pa.string()), *table.columns[1:]], schema=schema)
    with pytest.raises(dataset.SchemaError, match="episode_id"):
        dataset.check_table(holed, schema)


NAN = float("nan")
# (table, edit, column and row named, what the message says); every trust level given is the model's
IMPOSSIBLE_VALUES = {
    "nan_belief": (dataset.ROADS_FILE, set_values("belief_after", [NAN] * 7, [3]), "belief_after, row 3",
                   "not a finite number"),
    "negative_belief": (dataset.ROADS_FILE, set_values("belief_before", [-0.5, 1.5, 0, 0, 0, 0, 0], [4]),
                        "belief_before, row 4", "outside [0, 1]"),
    "belief_not_summing_to_1": (dataset.ROADS_FILE, set_values("belief_after", [0.5] * 7, [2]),
                                "belief_after, row 2", "sum to 3.5"),
    "belief_of_two_levels": (dataset.ROADS_FILE, set_values("belief_after", [0.5, 0.5], [6]),
                             "belief_after, row 6", "a belief of 2 entries, not 7"),
    "reported_trust_99": (dataset.ROADS_FILE, set_values("reported_trust", 99, [3]), "reported_trust, row 3",
                          "99 is not a trust level"),
    "negative_true_trust": (dataset.ROADS_FILE, set_values("trust_before", -3, [1]), "trust_before, row 1",
                            "-3 is not a trust level"),
    "duplicated_episode": (dataset.EPISODES_FILE, duplicate_row(1), "episode_id, row 48",
                           "a second row of episode_id"),
    "duplicated_road": (dataset.ROADS_FILE, duplicate_row(5), "index, row",
                        "a second row of episode_id"),
    "roads_of_no_episode": (dataset.ROADS_FILE, set_values("episode_id", "p00000-phi1-nowhere", [3]),
                            "episode_id, row 3",
                            "'p00000-phi1-nowhere' is not an episode of episodes.parquet"),
}
LEVELS = tuple(range(1, 8))


@pytest.mark.parametrize("case", sorted(IMPOSSIBLE_VALUES))
def test_impossible_values_are_refused_naming_the_file_column_and_row(case, model_study, tmp_path):
    """A table of the right schema holding impossible values is one InputError, on every read (trust
    against the levels of the study's driver model when the reader is given them)."""
    file_name, edit, place, problem = IMPOSSIBLE_VALUES[case]
    study = study_copy(model_study, tmp_path / "study", file_name, edit)
    levels = {"trust_levels": LEVELS} if "trust" in case else {}
    with pytest.raises(InputError) as info:
        dataset.read_episodes(study, **levels)
        dataset.read_roads(study, **levels)
    assert info.value.source == str(study / file_name) and info.value.place.startswith(place)
    assert problem in info.value.problem and "rebuild" in info.value.fix


def test_kinematics_of_no_episode_are_refused(model_study, tmp_path):
    study = study_copy(model_study, tmp_path / "study")
    row = {"episode_id": ["nowhere"], "time": [0.0], "x": [1.0], "y": [2.0], "speed": [0.0],
           "lane": ["A-B_1"], "mode": ["autopilot"]}
    dataset.write_table(dataset.table_from_columns(row, dataset.KINEMATICS_SCHEMA),
                        study / dataset.KINEMATICS_FILE)
    with pytest.raises(InputError, match="kinematics.parquet: episode_id, row 0: 'nowhere' is not an"):
        dataset.read_kinematics(study)


def test_a_finished_study_has_possible_values(model_study):
    episodes = dataset.read_episodes(model_study, trust_levels=LEVELS)
    roads = dataset.read_roads(model_study, trust_levels=LEVELS)
    assert len(episodes) == 48 and set(roads["episode_id"]) == set(episodes["episode_id"])


@pytest.mark.parametrize(("engine", "command"), [("live", "trustroute live CONFIG --out DIR"),
                                                 ("sumo", "trustroute study CONFIG --out DIR")])
def test_a_study_without_a_manifest_is_told_the_command_that_writes_it(tmp_path, engine, command):
    (tmp_path / dataset.STUDY_FILE).write_text(json.dumps({"config_hash": "x", "config": {"engine": engine}}))
    with pytest.raises(InputError) as error:
        dataset.read_manifest(tmp_path)
    assert error.value.place == dataset.MANIFEST_FILE and f"`{command}`" in error.value.fix


def test_a_folder_of_logs_is_told_to_import_them_and_a_missing_folder_is_named_missing(tmp_path, capsys):
    """A researcher's first mistakes: `trustroute fit` (or analyze, plan --pilot) on the authors' raw
    CSV logs, which the importer turns into a study, or on a path that is not there."""
    from tests.cli import run_cli

    logs = tmp_path / "checkout"
    (logs / "trust_level_record" / "driver_4").mkdir(parents=True)
    (logs / "trust_level_record" / "driver_4" / "log.csv").write_text("a\n")
    with pytest.raises(InputError) as error:
        dataset.read_manifest(logs)
    assert f"`trustroute import carla-logs {logs} --out STUDY`" in error.value.fix
    for missing, problem in ((tmp_path / "nope", "no such directory"),
                             (logs / "trust_level_record" / "driver_4" / "log.csv", "not a directory")):
        code, out, err = run_cli(capsys, "fit", str(missing), "--out", str(tmp_path / "driver.json"))
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert f"{missing}: {problem} (fix: pass the folder" in err, err


def test_a_package_s_table_is_found_once_per_read(model_study, tmp_path, monkeypatch):
    """A package's tables lie in its tables/ folder: a table read looks once whether the folder it
    is given is a package, however many of its files it reads (the table, the episodes its rows
    belong to)."""
    import shutil

    from trustroute.core import package

    tables = tmp_path / "package" / package.PACKAGE_TABLES_DIR
    tables.mkdir(parents=True)
    for name in (dataset.EPISODES_FILE, dataset.ROADS_FILE):
        shutil.copyfile(model_study / name, tables / name)
    (tmp_path / "package" / package.PACKAGE_CONFIG_FILE).write_text("{}")
    asked = []
    is_package = package.is_package
    monkeypatch.setattr(package, "is_package", lambda folder: asked.append(folder) or is_package(folder))
    roads = dataset.read_study_table(tmp_path / "package", "roads")
    assert roads.equals(dataset.read_study_table(model_study, "roads"))
    assert asked == [tmp_path / "package", model_study]
    asked.clear()
    assert dataset.read_incidents_table(tmp_path / "package").num_rows == 0
    assert asked == [tmp_path / "package"]


def test_a_live_package_s_table_of_an_earlier_form_reads_by_the_package_s_schema(model_study, tmp_path):
    """A live study's package holds its episodes without seeds (package.package_schema); one that
    ends before the columns added since (ADDED_COLUMNS) reads by that schema with those columns
    null; a table of no schema a package holds, or of impossible values, is refused with a package's
    fix, not a study directory's."""
    from trustroute.core import package

    folder = tmp_path / "package"
    (folder / package.PACKAGE_TABLES_DIR).mkdir(parents=True)
    (folder / package.PACKAGE_CONFIG_FILE).write_text("{}")
    path = package.table_path(folder, dataset.EPISODES_FILE)
    added = list(dataset.ADDED_COLUMNS["episodes"])
    earlier = pq.read_table(model_study / dataset.EPISODES_FILE).drop_columns(["seed", *added])
    pq.write_table(earlier, path)
    episodes = dataset.read_study_table(folder, "episodes")
    assert episodes.schema.equals(package.package_schema(dataset.EPISODES_SCHEMA, "episodes", people=True))
    assert episodes.drop_columns(added).equals(earlier.replace_schema_metadata(None))
    assert all(episodes.column(name).null_count == episodes.num_rows for name in added)
    pq.write_table(earlier.drop_columns(["spec"]), path)
    with pytest.raises(InputError) as error:
        dataset.read_study_table(folder, "episodes")
    assert (error.value.source, error.value.place) == (str(path), "schema")
    assert error.value.fix == package.PACKAGE_TABLE_FIX
    pq.write_table(pa.concat_tables([earlier, earlier.slice(0, 1)]), path)
    with pytest.raises(InputError) as error:
        dataset.read_study_table(folder, "episodes")
    assert error.value.place == f"episode_id, row {earlier.num_rows}"
    assert error.value.fix == package.PACKAGE_TABLE_FIX
