"""Finding roads by junction, street and point, junction distances between road sets, and
`trustroute town roads`."""

from __future__ import annotations

import json

import pytest

from tests.cli import run_cli
from trustroute.networks.road_lookup import (
    distance_to_road,
    junctions_apart,
    road_rows,
    road_streets,
    roads_into,
    roads_on_street,
    street_names,
    waypoint_legs,
)
from trustroute.networks.town import town_from_dict

# A square B-C-D-E with a bent road B-C (its shape leaves the straight line) and street names.
SQUARE = {
    "junctions": {"B": [0, 0], "C": [100, 0], "D": [100, 100], "E": [0, 100]},
    "roads": [["B", "C"], ["C", "D"], ["D", "E"], ["E", "B"]],
    "incidents": {r: "none" for r in ["B-C", "C-B", "C-D", "D-C", "D-E", "E-D", "E-B", "B-E"]},
    "geometry": {
        "B-C": {"shape": [[0, 0], [50, -40], [100, 0]], "street": "Low Road"},
        "C-B": {"shape": [[100, 0], [50, -40], [0, 0]], "street": "Low Road"},
        "C-D": {"shape": [[100, 0], [100, 100]], "street": "East Lane; High Street"},
        "E-D": {"shape": [[0, 100], [100, 100]], "street": "High Street"},
    },
}


LOOP = {**SQUARE, "geometry": {}, "one_way": [["B", "C"], ["C", "D"], ["D", "E"], ["E", "B"]],
        "incidents": {r: "none" for r in ["B-C", "C-D", "D-E", "E-B"]}}  # one way round the square


@pytest.fixture
def square():
    return town_from_dict(SQUARE, "square.json")


def test_roads_into_a_junction(square, town):
    assert roads_into(square, "C") == {"B-C", "D-C"}
    assert roads_into(town, "L") == {"K-L", "E-L", "H-L"}


def test_roads_on_a_street_split_joined_names_and_ignore_case(square):
    assert road_streets(square, "C-D") == ("East Lane", "High Street")
    assert roads_on_street(square, "high street") == {"C-D", "E-D"}
    assert roads_on_street(square, " Low Road ") == {"B-C", "C-B"}
    assert roads_on_street(square, "High") == frozenset()
    assert street_names(square) == ("East Lane", "High Street", "Low Road")


def test_distance_follows_the_shape_not_the_straight_line(square):
    # (50, -40) lies on the bent road's shape, 40 m from the straight line between B and C.
    assert distance_to_road(square, "B-C", (50, -40)) == pytest.approx(0.0)
    assert distance_to_road(square, "D-E", (50, -40)) == pytest.approx(140.0)
    rows = road_rows(square, near=(50, -40), limit=2)
    assert [r.road for r in rows] == ["B-C", "C-B"] and rows[0].street == "Low Road"
    assert [r.road for r in road_rows(square, street="High Street")] == ["C-D", "E-D"]


def test_junctions_apart_counts_the_junctions_passed(square, town):
    assert junctions_apart(square, {"B-C"}, {"B-C"}) == 0
    assert junctions_apart(square, {"B-C"}, {"C-D"}) == 1
    assert junctions_apart(square, {"B-C"}, {"E-B"}) == 3  # no U-turn at C: round the square
    assert junctions_apart(town, {"E-A"}, {"B-G", "F-G", "I-G"}) == 2
    assert junctions_apart(town_from_dict(LOOP, "loop.json"), {"C-D"}, {"B-C"}) == 3


def test_waypoint_legs_run_from_the_start_through_each_set(town):
    legs = waypoint_legs(town, "E-A", [("v1", roads_into(town, "G")), ("v2", roads_into(town, "J")),
                                        ("v3", roads_into(town, "L"))])
    assert [(leg.source, leg.target, leg.junctions) for leg in legs] == [
        ("start", "v1", 2), ("v1", "v2", 2), ("v2", "v3", 2)]


def test_an_unreachable_set_has_no_distance():
    town = town_from_dict(LOOP, "loop.json")
    assert junctions_apart(town, {"B-C"}, {"C-B"}) is None  # C-B does not exist on the one-way loop
    assert waypoint_legs(town, "B-C", [("v", frozenset({"C-B"}))])[0].junctions is None


def test_town_roads_near_a_point_and_on_a_street(capsys, tmp_path):
    town = tmp_path / "square.json"
    town.write_text(json.dumps({
        "junctions": {"B": [0, 0], "C": [100, 0], "D": [100, 100], "E": [0, 100]},
        "roads": [["B", "C"], ["C", "D"], ["D", "E"], ["E", "B"]],
        "incidents": {r: "none" for r in ["B-C", "C-B", "C-D", "D-C", "D-E", "E-D", "E-B", "B-E"]},
        "geometry": {"E-D": {"shape": [[0, 100], [50, 130], [100, 100]], "street": "High Street"}}}))
    code, out, _ = run_cli(capsys, "town", "roads", str(town), "--near", "50", "130", "--limit", "2")
    assert code == 0
    assert out.splitlines() == ["E-D  116.6 m  none  High Street  0.0 m away",
                                "D-E  100.0 m  none  (no street name)  30.0 m away"]
    code, out, _ = run_cli(capsys, "town", "roads", str(town), "--street", "HIGH STREET", "--json")
    assert code == 0 and [r["road"] for r in json.loads(out)["roads"]] == ["E-D"]
    code, _, err = run_cli(capsys, "town", "roads", str(town), "--street", "Low Road")
    assert code == 2 and "no road is on a street named 'Low Road'" in err and "High Street" in err
