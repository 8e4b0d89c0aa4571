"""The town file's optional road keys: one-way roads, road geometry, the source SUMO net, turn
restrictions; a town without them keeps its content hash."""

from __future__ import annotations

import copy
import math

import pytest

from trustroute.core.errors import InputError
from trustroute.networks.road_geometry import SumoNetRef, check_sumo_net, file_sha256, polyline_length
from trustroute.networks.town import PENTAGON_TOWN_PATH, load_town, town_from_dict

SQUARE = {
    "junctions": {"A": [0, 0], "B": [100, 0], "C": [100, 100], "D": [0, 100]},
    "roads": [["A", "B"], ["B", "C"], ["C", "D"], ["D", "A"]],
    "incidents": {"A-B": "truck", "B-A": "none", "B-C": "none", "C-B": "none", "C-D": "none",
                  "D-C": "none", "D-A": "none", "A-D": "none"},
}


def square(**extra) -> dict:
    return {**copy.deepcopy(SQUARE), **extra}


def one_way_square() -> dict:
    """A ring A->B->C->D->A: every road one-way."""
    data = square(one_way=[["A", "B"], ["B", "C"], ["C", "D"], ["D", "A"]])
    data["incidents"] = {"A-B": "truck", "B-C": "none", "C-D": "none", "D-A": "none"}
    return data


def test_a_town_without_the_new_keys_keeps_its_hash():
    default, pentagon = load_town(), load_town(PENTAGON_TOWN_PATH)
    plain = town_from_dict(square())
    empty = town_from_dict(square(one_way=[], geometry={}))
    assert plain.content_hash == empty.content_hash
    assert not pentagon.one_way and not pentagon.geometry and pentagon.sumo_net is None
    assert not default.one_way and set(default.geometry) == set(default.states) and default.sumo_net is None
    assert all(set(default.neighbours[j]) == {w for u, w in
               (tuple(s.split("-")) for s in default.states) if u == j} for j in default.junctions)


def test_one_way_roads_have_one_direction():
    town = town_from_dict(one_way_square())
    assert town.states == ("A-B", "B-C", "C-D", "D-A")
    assert town.neighbours["A"] == ("B",)
    assert town.actions("D-A") == ("B",)
    assert town.successors("A-B") == ("B-C",)


def test_one_way_errors():
    data = one_way_square()
    data["incidents"]["B-A"] = "none"
    with pytest.raises(InputError, match="'B-A' is not a directed road"):
        town_from_dict(data)
    data = one_way_square()
    data["one_way"].append(["A", "C"])
    with pytest.raises(InputError, match="A-C is not listed in roads"):
        town_from_dict(data)
    data = one_way_square()
    data["one_way"].append(["B", "A"])
    with pytest.raises(InputError, match="one-way twice"):
        town_from_dict(data)
    # A-B one-way the other way round: B is a sink, A a source
    data = square(one_way=[["A", "B"], ["C", "B"]])
    del data["incidents"]["B-A"], data["incidents"]["B-C"]
    with pytest.raises(InputError, match="cut the town"):
        town_from_dict(data)


def test_geometry_gives_the_model_length():
    bent = [[0, 0], [50, -30], [100, 0]]
    back = {"shape": bent[::-1], "length": 99.5, "edges": ["e1"], "street": "Main"}
    town = town_from_dict(square(geometry={"A-B": {"shape": bent}, "B-A": back}))
    assert town.length("A-B") == pytest.approx(2 * math.hypot(50, 30))
    assert town.length("B-A") == 99.5
    assert town.length("B-C") == 100.0  # no geometry: the straight line
    assert town.geometry["B-A"].edges == ("e1",) and town.geometry["B-A"].street == "Main"
    assert town.content_hash != town_from_dict(square()).content_hash
    assert polyline_length(((0, 0), (3, 4))) == 5.0


def test_a_short_road_with_a_geometry_is_accepted():
    data = square()
    data["junctions"]["B"] = [5, 0]
    with pytest.raises(InputError, match="almost coincide"):
        town_from_dict(data)
    data["geometry"] = {"A-B": {"shape": [[1, 0], [4, 0]]}}
    assert town_from_dict(data).length("A-B") == 3.0


@pytest.mark.parametrize(("geometry", "message"), [
    ({"A-C": {"shape": [[0, 0], [1, 1]]}}, "not a directed road"),
    ({"A-B": {"shape": [[0, 0], [math.nan, 1]]}}, "finite numbers"),
    ({"A-B": {"shape": [[0, 0]]}}, "at least two"),
    ({"A-B": {"shape": [[0, 0], [0, 0]]}}, "not a positive number"),
    ({"A-B": {"shape": [[0, 0], [1, 0]], "length": -1}}, "not a positive number"),
    ({"A-B": {"shape": [[0, 0], [1, 0]], "lanes": 2}}, "unknown key"),
    ({"A-B": {"shape": [[0, 0], [1, 0]], "edges": "e1"}}, "SUMO edge ids"),
    ({"A-B": [[0, 0], [1, 0]]}, "expected an object"),
])
def test_geometry_errors_name_the_road(geometry, message):
    with pytest.raises(InputError, match=message) as error:
        town_from_dict(square(geometry=geometry), "town.json")
    assert "geometry" in error.value.one_line() and "town.json" in error.value.one_line()


def test_a_misspelt_geometry_key_names_the_closest():
    with pytest.raises(InputError) as error:
        town_from_dict(square(geometry={"A-B": {"shape": [[0, 0], [1, 0]], "lenght": 1}}), "town.json")
    assert error.value.place == "geometry.A-B.lenght"
    assert error.value.fix.startswith("write length, the closest key, or one of shape, length, edges, street")


def test_sumo_net_reference_and_hash(tmp_path):
    net = tmp_path / "city.net.xml"
    net.write_text("<net/>")
    town_file = tmp_path / "town.json"
    reference = {"file": "city.net.xml", "sha256": file_sha256(net)}
    town = town_from_dict(square(sumo_net=reference), str(town_file))
    assert town.sumo_net == SumoNetRef("city.net.xml", file_sha256(net))
    assert check_sumo_net(town.sumo_net, str(town_file)) == net
    net.write_text("<net changed=''/>")
    with pytest.raises(InputError, match="has changed since the town was imported"):
        check_sumo_net(town.sumo_net, str(town_file))
    net.unlink()
    with pytest.raises(InputError, match="does not exist"):
        check_sumo_net(town.sumo_net, str(town_file))
    with pytest.raises(InputError, match="sumo_net"):
        town_from_dict(square(sumo_net={"file": "city.net.xml", "sha256": "abc"}))


def test_a_shaped_road_may_join_close_junctions_but_not_one_point():
    data = square(geometry={"A-B": {"shape": [[0, 0], [50, 40], [100, 0]]}})
    data["junctions"]["B"] = [3.0, 0.0]  # 3 m from A: allowed, the road has its own course
    assert town_from_dict(copy.deepcopy(data)).length("A-B") == pytest.approx(2 * math.hypot(50, 40))
    data["junctions"]["B"] = list(data["junctions"]["A"])
    with pytest.raises(InputError, match="road A-B is 0 m long"):
        town_from_dict(data)


def test_turns_replace_the_rule_for_the_roads_they_name():
    town = town_from_dict(square(turns={"A-B": ["C", "A"], "C-D": ["A"]}))
    plain = town_from_dict(square())
    assert town.turns == {"A-B": ("A", "C"), "C-D": ("A",)}
    assert plain.actions("A-B") == ("C",) and town.actions("A-B") == ("A", "C")   # a U-turn allowed
    assert town.successors("C-D") == ("D-A",)
    assert all(town.actions(road) == plain.actions(road) for road in town.states if road not in town.turns)
    row = town.successor_table[town.state_index("A-B")]
    assert sorted(row[row >= 0].tolist()) == sorted(town.state_index(r) for r in ("B-A", "B-C"))
    assert town.content_hash != plain.content_hash
    assert town_from_dict(square(turns={})).content_hash == plain.content_hash
    assert town_from_dict(square(turns={"C-D": ["A"], "A-B": ["A", "C"]})).content_hash == town.content_hash


def test_a_town_without_turns_keeps_its_moves():
    default = load_town()
    assert default.turns == {}
    assert all(default.actions(road) == (tuple(w for w in default.neighbours[road.split("-")[1]]
                                               if w != road.split("-")[0])
                                         or (road.split("-")[0],)) for road in default.states)


@pytest.mark.parametrize(("turns", "message"), [
    ({"A-C": ["D"]}, "'A-C' is not a directed road"),
    ({"A-B": ["D"]}, "B-D is not a directed road"),
    ({"A-B": []}, "non-empty list"),
    ({"A-B": ["C", "C"]}, "each once"),
    ({"A-B": "C"}, "non-empty list"),
    (["A-B"], "expected an object"),
])
def test_turn_errors_name_the_key(turns, message):
    with pytest.raises(InputError, match=message) as error:
        town_from_dict(square(turns=turns), "town.json")
    assert "turns" in error.value.one_line() and "town.json" in error.value.one_line()
