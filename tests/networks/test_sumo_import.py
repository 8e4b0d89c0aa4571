"""SUMO nets as towns: the decision-point graph on hand-made nets (a one-way street, a dead end, a
chain of degree-2 junctions, a roundabout, parallel roads), checked against an independent count
from sumolib; road lengths against sumolib's edge lengths; the edges of every road form a chain of
the net."""

from __future__ import annotations

import math

import pytest
import sumolib

from tests.networks.sumo_nets import (
    WHEEL_NODES,
    WHEEL_ROADS,
    build_plain_net,
    passenger_edges,
    sumolib_decision_junctions,
)
from trustroute.networks.road import Road
from trustroute.networks.sumo_import import decision_graph, junction_names, read_net_graph


def graph_of(net_path):
    return decision_graph(read_net_graph(net_path), str(net_path))


def directed(graph) -> set[str]:
    return {Road(r.source, r.target).id for r in graph.roads}


def check_roads_follow_the_net(graph, net_path) -> None:
    """Every road is a chain of passenger edges of the net from its junction to its junction, and
    its length is the sum of sumolib's edge lengths; its shape runs along those edges."""
    net = sumolib.net.readNet(str(net_path))
    for road in graph.roads:
        edges = [net.getEdge(e.id) for e in road.edges]
        assert all(e.allows("passenger") for e in edges)
        assert edges[0].getFromNode().getID() == graph.junction_ids[road.source]
        assert edges[-1].getToNode().getID() == graph.junction_ids[road.target]
        for first, second in zip(edges, edges[1:], strict=False):
            assert first.getToNode() == second.getFromNode()
        assert road.length == pytest.approx(sum(e.getLength() for e in edges), abs=1e-3)
        assert road.shape[0] == pytest.approx(edges[0].getShape()[0])
        assert road.shape[-1] == pytest.approx(edges[-1].getShape()[-1])


def test_one_way_street_stays_one_way(tmp_path):
    roads = [r for r in WHEEL_ROADS if r != ("b", "c")]
    net = build_plain_net(tmp_path, "oneway", WHEEL_NODES, roads, one_way=[("b", "c")])
    graph = graph_of(net)
    assert set(graph.junction_ids.values()) == sumolib_decision_junctions(net) == set("abcde")
    assert "b-c" in directed(graph) and "c-b" not in directed(graph)
    assert len(graph.roads) == 2 * len(roads) + 1
    check_roads_follow_the_net(graph, net)


def test_edges_closed_to_cars_are_left_out(tmp_path):
    net = build_plain_net(tmp_path, "footway", WHEEL_NODES, [*WHEEL_ROADS, ("a", "c")],
                          allow={("a", "c"): "pedestrian", ("c", "a"): "pedestrian"})
    graph = graph_of(net)
    assert "a-c" not in directed(graph) and "c-a" not in directed(graph)
    assert graph.dropped["edges closed to passenger cars"] == 2
    assert len(graph.roads) == 2 * len(WHEEL_ROADS)


def test_dead_end_and_chain_of_degree_two_junctions(tmp_path):
    """A spur a-m-x to a dead end x, and the side a-b drawn through p1, p2, p3: the dead end ends a
    road, the degree-2 junctions m, p1, p2, p3 are passed without a choice and disappear."""
    nodes = {**WHEEL_NODES, "m": (-100, -100), "x": (-200, -200),
             "p1": (75, 0), "p2": (150, -20), "p3": (225, 0)}
    roads = [r for r in WHEEL_ROADS if r != ("a", "b")] + [
        ("a", "m"), ("m", "x"), ("a", "p1"), ("p1", "p2"), ("p2", "p3"), ("p3", "b")]
    net = build_plain_net(tmp_path, "chain", nodes, roads)
    graph = graph_of(net)
    assert set(graph.junction_ids.values()) == sumolib_decision_junctions(net) == {*"abcde", "x"}
    assert directed(graph) >= {"a-x", "x-a", "a-b", "b-a"}
    assert len(graph.roads) == 2 * len(WHEEL_ROADS) + 2
    a_b = next(r for r in graph.roads if (r.source, r.target) == ("a", "b"))
    assert [e.id for e in a_b.edges] == ["a_p1", "p1_p2", "p2_p3", "p3_b"]
    assert len(a_b.shape) >= 4  # the bend at p2 is kept
    check_roads_follow_the_net(graph, net)


def test_roundabout(tmp_path):
    """A one-way ring r1..r4 with an arm from each ring junction to an outer square: every ring
    junction is a decision point (go round or leave), and the ring stays one-way."""
    ring = {"r1": (0, -30), "r2": (30, 0), "r3": (0, 30), "r4": (-30, 0)}
    outer = {"o1": (0, -200), "o2": (200, 0), "o3": (0, 200), "o4": (-200, 0)}
    ring_edges = [("r1", "r2"), ("r2", "r3"), ("r3", "r4"), ("r4", "r1")]
    arms = [(f"r{i}", f"o{i}") for i in range(1, 5)]
    square = [("o1", "o2"), ("o2", "o3"), ("o3", "o4"), ("o4", "o1")]
    net = build_plain_net(tmp_path, "roundabout", {**ring, **outer}, arms + square, one_way=ring_edges)
    graph = graph_of(net)
    assert set(graph.junction_ids.values()) == sumolib_decision_junctions(net) == set(ring) | set(outer)
    assert {Road(u, v).id for u, v in ring_edges} <= directed(graph)
    assert not {Road(v, u).id for u, v in ring_edges} & directed(graph)
    assert len(graph.roads) == 4 + 2 * 4 + 2 * 4
    check_roads_follow_the_net(graph, net)


def test_parallel_roads_keep_their_own_names(tmp_path):
    """A second street from a to b through q (no choice at q) would share the name a-b: q becomes
    a junction of the town, counted as added."""
    nodes = {**WHEEL_NODES, "q": (150, -100)}
    net = build_plain_net(tmp_path, "parallel", nodes, [*WHEEL_ROADS, ("a", "q"), ("q", "b")])
    graph = graph_of(net)
    assert "q" not in sumolib_decision_junctions(net)
    assert set(graph.junction_ids) == {*"abcde", "q"} and graph.added_junctions == 1
    assert directed(graph) >= {"a-b", "a-q", "q-b", "b-q", "q-a"}
    assert "1 junction without a choice kept" in graph.summary()
    check_roads_follow_the_net(graph, net)


def test_only_the_largest_strongly_connected_part_is_kept(tmp_path):
    nodes = {**WHEEL_NODES, "f": (600, 0), "g": (900, 0), "h": (600, 300)}
    # a one-way link from the wheel to a separate triangle f-g-h: the triangle is its own part
    net = build_plain_net(tmp_path, "parts", nodes, [*WHEEL_ROADS, ("f", "g"), ("g", "h"), ("h", "f")],
                          one_way=[("b", "f")])
    graph = graph_of(net)
    assert set(graph.junction_ids) == set("abcde")
    assert graph.dropped["edges outside the largest strongly connected part"] == 7
    assert graph.dropped["other strongly connected parts"] == 1
    assert "dropped 7 edges outside" in graph.summary()
    assert graph.summary().endswith(", 1 other strongly connected part")


def test_the_summary_counts_one_in_the_singular():
    from trustroute.networks.sumo_import import DROPPED_ONE, DecisionGraph

    one = DecisionGraph(junction_ids={}, positions={}, roads=(), dropped=dict.fromkeys(DROPPED_ONE, 1))
    assert one.summary() == "dropped " + ", ".join(f"1 {what}" for what in DROPPED_ONE.values())
    assert "1 edge closed to passenger cars" in one.summary() and "edges" not in one.summary()
    two = DecisionGraph(junction_ids={}, positions={}, roads=(), dropped=dict.fromkeys(DROPPED_ONE, 2))
    assert two.summary() == "dropped " + ", ".join(f"2 {what}" for what in DROPPED_ONE)


def test_passenger_edges_are_all_used_on_hand_made_nets(tmp_path):
    net = build_plain_net(tmp_path, "wheel", WHEEL_NODES, WHEEL_ROADS)
    graph = graph_of(net)
    used = sorted(e.id for r in graph.roads for e in r.edges)
    assert used == sorted(e.getID() for e in passenger_edges(sumolib.net.readNet(str(net)).getEdges()))


def test_junction_names_are_stable_unique_and_valid():
    ids = ["cluster_1_2", "a-b", "a_b", "x" * 80, "#3", ":j"]
    names = junction_names(ids)
    assert names == junction_names(list(reversed(ids)))
    assert len(set(names.values())) == len(ids)
    assert all(len(n) <= 64 and n.replace("_", "").isalnum() for n in names.values())
    assert names["cluster_1_2"] == "cluster_1_2"


def test_road_geometry_length_is_summed(tmp_path):
    net = build_plain_net(tmp_path, "wheel", WHEEL_NODES, WHEEL_ROADS)
    graph = graph_of(net)
    for road in graph.roads:
        straight = math.dist(graph.positions[road.source], graph.positions[road.target])
        assert 0 < road.length <= straight + 1e-6  # edges stop short of the junction centres
