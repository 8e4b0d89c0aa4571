"""Malformed town files: each gives its own one-line error and exit code 2 through the CLI."""

from __future__ import annotations

import json

import pytest

from tests.cli import (
    assert_file_refused,
    assert_one_line_error,
    mutated,
    mutation_cases,
    refused_file,
    run_cli,
)
from trustroute.networks.town import DEFAULT_TOWN_PATH, load_town


def default_town() -> dict:
    return json.loads(DEFAULT_TOWN_PATH.read_text())


def unknown_junction(t: dict) -> None:
    t["roads"].append(["A", "Z"])


def duplicate_road(t: dict) -> None:
    t["roads"].append(["A", "B"])


def reversed_duplicate_road(t: dict) -> None:
    t["roads"].append(["B", "A"])


def self_loop(t: dict) -> None:
    t["roads"].append(["C", "C"])


def missing_incident(t: dict) -> None:
    del t["incidents"]["C-J"]


def extra_incident(t: dict) -> None:
    t["incidents"]["A-C"] = "none"


def unknown_incident_type(t: dict) -> None:
    t["incidents"]["A-B"] = "cow"


def non_numeric_coordinates(t: dict) -> None:
    t["junctions"]["D"] = ["-411", -566]


def one_coordinate(t: dict) -> None:
    t["junctions"]["D"] = [5.0]


def disconnected(t: dict) -> None:
    t["junctions"]["M"] = [2000, 2000]
    t["junctions"]["N"] = [2100, 2000]
    t["roads"].append(["M", "N"])
    t["incidents"]["M-N"] = "none"
    t["incidents"]["N-M"] = "none"


def missing_roads_key(t: dict) -> None:
    del t["roads"]


def dashed_junction_name(t: dict) -> None:
    t["junctions"]["X-Y"] = [1, 1]


# (mutation, the place the message must name, words of the specific problem)
CASES = [
    (unknown_junction, "roads[18]", "unknown junction 'Z'"),
    (duplicate_road, "roads[18]", "listed twice"),
    (reversed_duplicate_road, "roads[18]", "listed twice"),
    (self_loop, "roads[18]", "self-loop"),
    (missing_incident, "incidents.C-J", "missing incident entry"),
    (extra_incident, "incidents.A-C", "not a directed road"),
    (unknown_incident_type, "incidents.A-B", "unknown incident type 'cow'"),
    (non_numeric_coordinates, "junctions.D", "not two finite numbers"),
    (one_coordinate, "junctions.D", "not two finite numbers"),
    (disconnected, "roads", "disconnected: M, N"),
    (missing_roads_key, "roads", "missing key 'roads'"),
    (dashed_junction_name, "junctions.X-Y", "contain no '-'"),
]


@pytest.mark.parametrize("mutate, place, problem", mutation_cases(CASES))
def test_malformed_town_gives_its_error_and_exit_2(tmp_path, capsys, mutate, place, problem):
    assert_file_refused(capsys, load_town, "--town", mutated(default_town(), mutate), tmp_path / "town.json",
                        place, problem)


def test_bad_json_names_line_and_column(tmp_path, capsys):
    path = tmp_path / "town.json"
    path.write_text('{"junctions": {"A": [0, 0],}\n')
    code, _, err = run_cli(capsys, "model", "--town", str(path))
    assert_one_line_error(code, err, str(path), "line 1 column", "not valid JSON")


def test_missing_file(tmp_path, capsys):
    code, _, err = run_cli(capsys, "model", "--town", str(tmp_path / "absent.json"))
    assert_one_line_error(code, err, "absent.json", "cannot read the town file")


def test_top_level_not_an_object(tmp_path, capsys):
    path = tmp_path / "town.json"
    path.write_text("[1, 2]")
    code, _, err = run_cli(capsys, "model", "--town", str(path))
    assert_one_line_error(code, err, "top level", "expected a JSON object")


def test_the_unmodified_default_passes(tmp_path, capsys):
    path = tmp_path / "town.json"
    path.write_text(json.dumps(default_town()))
    code, out, err = run_cli(capsys, "model", "--town", str(path))
    assert code == 0 and err == ""
    assert "12 junctions, 18 two-way roads, 36 states" in out


def test_every_missing_incident_is_counted_in_one_line(tmp_path, capsys):
    """A town listing incidents for one direction of each road only: 18 entries missing, the first
    five named and the rest counted, in one line."""
    data = default_town()
    kept = {f"{u}-{v}" for u, v in data["roads"]}
    missing = sorted(set(data["incidents"]) - kept)
    data["incidents"] = {road: kind for road, kind in data["incidents"].items() if road in kept}
    assert len(missing) == len(data["roads"]) == 18
    problem = f"missing incident entries for 18 directed roads: {', '.join(missing[:5])} and 13 more"
    error = assert_file_refused(capsys, load_town, "--town", data, tmp_path / "town.json",
                                f"incidents.{missing[0]}", problem)
    assert error.problem == problem


def test_a_few_missing_incidents_are_all_named(tmp_path):
    data = default_town()
    for road in ("C-J", "A-B", "J-C"):
        del data["incidents"][road]
    error = refused_file(load_town, data, tmp_path / "town.json")
    assert error.problem == "missing incident entries for 3 directed roads: A-B, C-J, J-C"
