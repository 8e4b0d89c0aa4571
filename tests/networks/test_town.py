"""The town: default shape, actions, lengths, hashing, shortest paths (against Bellman-Ford)."""

import itertools
import json
import math

import pytest

from trustroute.networks.town import DEFAULT_TOWN_PATH, PENTAGON_TOWN_PATH, load_town, town_from_dict


def test_default_town_shape(town):
    assert len(town.junctions) == 12
    assert len(town.roads) == 18
    assert len(town.states) == 36
    assert all(len(town.neighbours[j]) == 3 for j in town.junctions)


def test_actions_exclude_u_turns(town):
    for state in town.states:
        came_from, at = state.split("-")
        actions = town.actions(state)
        assert came_from not in actions
        assert set(actions) == set(town.neighbours[at]) - {came_from}


def test_content_hash_ignores_formatting(tmp_path, town):
    data = json.loads(DEFAULT_TOWN_PATH.read_text())
    (tmp_path / "t.json").write_text(json.dumps(data, indent=None))
    assert load_town(tmp_path / "t.json").content_hash == town.content_hash


@pytest.mark.parametrize("name", ["grid.net.xml", "grid.net.xml.gz", "map.osm", "Map.OSM.xml"])
def test_a_sumo_net_or_osm_file_given_as_a_town_names_the_import(tmp_path, name):
    from trustroute.core.errors import InputError

    source = tmp_path / name
    source.write_text('<net version="1.20"></net>\n')
    with pytest.raises(InputError) as error:
        load_town(source, given="--town")
    line = error.value.one_line()
    assert "not a town file (JSON)" in line and "not valid JSON" not in line
    assert f"trustroute town import {source} --out town.json, then pass town.json with --town" in line


def test_shortest_route_reaches_target(town):
    route = town.shortest_route("E-A", {"B-G", "F-G", "I-G"})
    assert route[0] == "E-A" and route[-1] in {"B-G", "F-G", "I-G"}
    for a, b in zip(route, route[1:], strict=False):
        assert b in town.successors(a)


def small_town_with_dead_end():
    return town_from_dict({
        "junctions": {"A": [0, 0], "B": [100, 0], "C": [100, 100], "D": [200, 0]},
        "roads": [["A", "B"], ["B", "C"], ["B", "D"], ["C", "D"]],
        "incidents": {"A-B": "none", "B-A": "truck", "B-C": "obstacle", "C-B": "none",
                      "B-D": "pedestrian", "D-B": "none", "C-D": "none", "D-C": "none"},
    }, "<small>")


def test_dead_end_allows_the_u_turn():
    town = small_town_with_dead_end()
    assert town.actions("B-A") == ("B",)
    assert town.successors("B-A") == ("A-B",)
    assert town.actions("A-B") == ("C", "D")


def test_states_sorted_and_indexed(town):
    assert list(town.states) == sorted(town.states)
    for i, state in enumerate(town.states):
        assert town.state_index(state) == i
        u, v = state.split("-")
        assert v in town.neighbours[u]


def test_lengths_are_euclidean_and_symmetric(town):
    pentagon = load_town(PENTAGON_TOWN_PATH)  # no geometry: centre-to-centre distances
    assert not pentagon.geometry
    for state in pentagon.states:
        u, v = state.split("-")
        (x1, y1), (x2, y2) = pentagon.junctions[u], pentagon.junctions[v]
        assert pentagon.length(state) == math.hypot(x2 - x1, y2 - y1) > 0
    # Town01's lengths are its geometry's: straight roads to the millimetre, the outer streets longer.
    for state in town.states:
        u, v = state.split("-")
        (x1, y1), (x2, y2) = town.junctions[u], town.junctions[v]
        assert town.length(state) == town.geometry[state].length
        if len(town.geometry[state].shape) == 2:
            assert town.length(state) == pytest.approx(math.hypot(x2 - x1, y2 - y1), abs=5e-4)
        else:
            assert town.length(state) > math.hypot(x2 - x1, y2 - y1) + 100
        assert town.length(state) == town.length(f"{v}-{u}")
    route = ["E-A", "A-B", "B-G"]
    assert town.route_length(route) == town.length("A-B") + town.length("B-G")


def test_content_hash_changes_with_content(town):
    data = {"junctions": {k: list(v) for k, v in town.junctions.items()},
            "roads": [list(r) for r in town.roads], "incidents": dict(town.incidents)}
    data["incidents"]["A-B"] = "truck" if town.incidents["A-B"] != "truck" else "none"
    assert town_from_dict(data, "<changed>").content_hash != town.content_hash


def bellman_ford(town, start):
    """Shortest legal distance to every state by relaxation (independent of Dijkstra)."""
    dist = {s: math.inf for s in town.states}
    dist[start] = 0.0
    for _ in range(len(town.states)):
        for s in town.states:
            for nxt in town.successors(s):
                dist[nxt] = min(dist[nxt], dist[s] + town.length(nxt))
    return dist


def test_shortest_route_is_shortest(town):
    for start, targets in itertools.product(["E-A", "L-H", "B-C"], [{"B-G", "F-G", "I-G"},
                                                                    {"K-L"}, {"D-E", "A-E"}]):
        dist = bellman_ford(town, start)
        route = town.shortest_route(start, targets)
        assert route[0] == start and route[-1] in targets
        for a, b in zip(route, route[1:], strict=False):
            assert b in town.successors(a)
        best = min(dist[t] for t in targets) if start not in targets else 0.0
        assert town.route_length(route) == pytest.approx(best, rel=1e-12)


def test_shortest_route_start_is_target_and_unreachable(town):
    assert town.shortest_route("E-A", {"E-A"}) == ["E-A"]
    assert town.shortest_route("E-A", set()) is None
    assert town.reachable_states("E-A") == set(town.states)


def test_cached_moves_and_indices_match_their_definition(town):
    """Town.actions and Town.state_index (tables built once per town) agree with the definition:
    neighbours of V except U (U itself at a dead end), and the position in the sorted states."""
    from trustroute.networks.road import Road

    for i, road in enumerate(town.states):
        came_from, at = Road.parse(road)
        expected = tuple(w for w in town.neighbours[at] if w != came_from) or (came_from,)
        assert town.actions(road) == expected
        assert town.state_index(road) == i
    with pytest.raises(ValueError, match="Z-Y"):
        town.state_index("Z-Y")
