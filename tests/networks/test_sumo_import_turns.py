"""Turn restrictions of an imported town: the moves of every road against an independent count
from sumolib on hand-made nets (a forbidden left turn, a one-way street, a dead end with and
without its U-turn, a junction that only lets a car turn back), the same town from two imports,
and on grid nets with fringe roads that end without a turnaround every move of the town has a
connection in the net; synthesis and the trust-free route only take the allowed moves."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
import sumo
import sumolib

from tests.cli import run_cli
from tests.networks.sumo_nets import (
    WHEEL_NODES,
    WHEEL_ROADS,
    build_plain_net,
    car_connected,
    passenger_edges,
    sumolib_moves,
    unconnected_moves,
)
from trustroute.networks.road import Road
from trustroute.networks.sumo_import import decision_graph, read_net_graph
from trustroute.networks.sumo_net import find_binary
from trustroute.networks.town import load_town
from trustroute.networks.town_import import import_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.policies.model.trust_pomdp import TrustPOMDP

GRID6 = Path(sumo.SUMO_HOME) / "tools" / "game" / "grid6" / "grid6.net.xml"
DEAD_END = {**WHEEL_NODES, "f": (-200, 0)}   # f: a dead end beside a


def moves_as_edges(net_path: Path) -> dict[str, set[str]]:
    """The importer's moves of every road, as SUMO edge ids (on these nets a road is one edge)."""
    graph = decision_graph(read_net_graph(net_path), str(net_path))
    edge = {Road(r.source, r.target).id: r.edges[0].id for r in graph.roads}
    assert all(len(r.edges) == 1 for r in graph.roads)
    return {edge[road]: {edge[Road(Road.parse(road).to_junction, w).id] for w in moves}
            for road, moves in graph.moves.items()}


def test_a_forbidden_left_turn_is_not_a_move(tmp_path):
    # from a (south-west) into the centre e, turning to d (north-west) is a left turn
    net = build_plain_net(tmp_path, "left", WHEEL_NODES, WHEEL_ROADS, forbidden=[("a_e", "e_d")])
    assert moves_as_edges(net) == sumolib_moves(net)
    town = import_town(net, tmp_path / "town.json").town
    assert town.actions("a-e") == ("b", "c") and town.turns == {"a-e": ("b", "c")}
    assert "turns" in json.loads((tmp_path / "town.json").read_text())
    free_net = build_plain_net(tmp_path, "free", WHEEL_NODES, WHEEL_ROADS)
    free = import_town(free_net, tmp_path / "free.json").town
    assert free.actions("a-e") == ("b", "c", "d") and free.turns == {}
    assert unconnected_moves(town, net) == (0, sum(len(town.actions(r)) for r in town.states))


def test_a_one_way_street(tmp_path):
    roads = [r for r in WHEEL_ROADS if r != ("b", "c")]
    net = build_plain_net(tmp_path, "oneway", WHEEL_NODES, roads, one_way=[("b", "c")])
    assert moves_as_edges(net) == sumolib_moves(net)
    town = import_town(net, tmp_path / "town.json").town
    assert "c-b" not in town.states and town.actions("a-b") == ("c", "e")
    assert unconnected_moves(town, net)[0] == 0


def test_a_dead_end_turns_back_only_where_the_net_lets_it(tmp_path):
    net = build_plain_net(tmp_path, "dead", DEAD_END, [*WHEEL_ROADS, ("a", "f")])
    assert moves_as_edges(net) == sumolib_moves(net)
    town = import_town(net, tmp_path / "dead.json").town
    assert town.actions("a-f") == ("a",) and town.turns == {}   # the rule's own U-turn at a dead end
    # Without turnarounds a car that drives to f cannot leave it: both roads to and from f go.
    banned = build_plain_net(tmp_path, "ban", DEAD_END, [*WHEEL_ROADS, ("a", "f")], turnarounds=False)
    assert sumolib_moves(banned)["a_f"] == set()
    result = import_town(banned, tmp_path / "ban.json")
    assert "f" not in result.town.junctions and "a-f" not in result.town.states
    assert result.graph.dropped["roads the net's turns do not drive to and from the rest"] == 2
    assert unconnected_moves(result.town, banned)[0] == 0


def test_a_u_turn_where_nothing_else_is_connected(tmp_path):
    net = build_plain_net(tmp_path, "back", WHEEL_NODES, WHEEL_ROADS,
                          forbidden=[("a_e", "e_b"), ("a_e", "e_c"), ("a_e", "e_d")])
    assert moves_as_edges(net) == sumolib_moves(net)
    town = import_town(net, tmp_path / "town.json").town
    assert town.actions("a-e") == ("a",) and town.successors("a-e") == ("e-a",)
    assert town.turns["a-e"] == ("a",)


def test_importing_twice_gives_the_same_town(tmp_path):
    net = build_plain_net(tmp_path, "left", WHEEL_NODES, WHEEL_ROADS, forbidden=[("a_e", "e_d")])
    import_town(net, tmp_path / "one.json")
    import_town(net, tmp_path / "two.json")
    assert (tmp_path / "one.json").read_bytes() == (tmp_path / "two.json").read_bytes()
    assert load_town(tmp_path / "one.json").content_hash == load_town(tmp_path / "two.json").content_hash


def test_the_wheel_grid_net_has_no_move_without_a_connection(tmp_path):
    """grid6 (netconvert --no-turnarounds, connections of its own): the rule's moves on its
    junction graph miss connections (44 of 112 before turns were read), the town's none."""
    town = import_town(GRID6, tmp_path / "grid6.json").town
    missing, total = unconnected_moves(town, GRID6)
    assert (missing, total) == (0, sum(len(town.actions(r)) for r in town.states)) and total > 0
    # its fringe edges lead nowhere a car may drive: no road of the town runs along one
    net = sumolib.net.readNet(str(GRID6))
    traps = {e.getID() for e in passenger_edges(net.getEdges())
             if not any(car_connected(net, e.getID(), o.getID()) for o in e.getToNode().getOutgoing())}
    used = {edge for road in town.states for edge in town.geometry[road].edges}
    assert traps and not traps & used
    # the trust POMDP (and the product and belief-MDP search built on its table) offers those moves
    pomdp = TrustPOMDP(town, load_driver_model(None))
    offered = {(town.states[x], town.states[y]) for x, row in enumerate(pomdp.successor_table)
               for y in row.tolist() if y >= 0}
    assert offered == {(road, nxt) for road in town.states for nxt in town.successors(road)}


@pytest.mark.parametrize("turnarounds", [True, False])
def test_a_generated_grid_with_fringe_roads(tmp_path, turnarounds):
    net = tmp_path / "grid.net.xml"
    subprocess.run([find_binary("netgenerate"), "--grid", "--grid.number", "3", "--grid.length", "200",
                    "--grid.attach-length", "100", "-o", str(net), "--no-warnings",
                    *([] if turnarounds else ["--no-turnarounds"])], check=True, capture_output=True)
    town = import_town(net, tmp_path / "grid.json").town
    assert unconnected_moves(town, net)[0] == 0
    fringe = [j for j in town.junctions if len(town.neighbours[j]) == 1]
    # with turnarounds the fringe dead ends stay (a car turns back there), without they go
    assert bool(fringe) == turnarounds


def test_synthesis_and_the_free_route_take_only_allowed_moves(tmp_path, capsys):
    net = build_plain_net(tmp_path, "left", WHEEL_NODES, WHEEL_ROADS, forbidden=[("a_e", "e_d")])
    import_town(net, tmp_path / "left.json")
    document = json.loads((tmp_path / "left.json").read_text())
    document["turns"] = {}
    (tmp_path / "free.json").write_text(json.dumps(document))
    spec = tmp_path / "spec.toml"
    spec.write_text('name = "left"\nstart = "a-e"\nformula = "F v1"\n\n[states]\nv1 = ["e-d"]\n')
    bounds = {}
    for name in ("left", "free"):
        code, out, err = run_cli(capsys, "synth", str(spec), "--town", str(tmp_path / f"{name}.json"),
                                 "--horizon", "1", "--json", "--out", str(tmp_path / f"{name}.policy.json"))
        assert code == 0, err
        bounds[name] = json.loads(out)
    # one junction on from a-e: e-d only by the forbidden left turn
    assert bounds["left"]["upper"] == 0.0 and bounds["free"]["lower"] > 0.0
    code, out, err = run_cli(capsys, "baseline", str(spec), "--town", str(tmp_path / "left.json"), "--json")
    assert code == 0, err
    route = json.loads(out)["route"]
    assert route[0] == "a-e" and route[1] != "e-d" and route[-1] == "e-d"
    town = load_town(tmp_path / "left.json")
    assert all(b.split("-")[1] in town.actions(a) for a, b in zip(route, route[1:], strict=False))
    assert unconnected_moves(town, net)[0] == 0
