"""The SUMO net of the default town: loads in libsumo, lengths, connections, cache, bad input."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest
import sumolib

from trustroute.core.cache import entry_lock_path as cache_entry_lock
from trustroute.core.errors import InputError
from trustroute.networks.road import Road
from trustroute.networks.sumo_net import build_net, net_counts
from trustroute.networks.town import PENTAGON_TOWN_PATH, load_town


@pytest.fixture(scope="module")
def built(town, tmp_path_factory):
    return build_net(town, cache_dir=tmp_path_factory.mktemp("nets"))


@pytest.fixture(scope="module")
def net(built):
    return sumolib.net.readNet(str(built.path), withInternal=True)


def _internal_length(net, connection) -> float:
    """Length of the internal lanes a vehicle drives through for one connection."""
    total = 0.0
    via = connection.getViaLaneID()
    while via:
        lane = net.getLane(via)
        total += lane.getLength()
        via = next((c.getToLane().getID() for c in lane.getOutgoing()
                    if c.getToLane().getEdge().getFunction() == "internal"), None)
    return total


def test_net_loads_in_libsumo(built, town):
    import libsumo

    libsumo.start(["sumo", "-n", str(built.path), "--no-step-log", "true", "--no-warnings", "true"])
    try:
        edges = {e for e in libsumo.edge.getIDList() if not e.startswith(":")}
        libsumo.simulationStep()
    finally:
        libsumo.close()
    assert edges == set(town.states)


def test_counts(built, town):
    assert (built.edges, built.junctions) == (len(town.states), len(town.junctions))
    assert built.connections == sum(len(town.successors(s)) for s in town.states)
    pedestrian_roads = {frozenset(Road.parse(r)) for r in town.states if town.incident(r) == "pedestrian"}
    assert built.crossings == 2 * len(pedestrian_roads)


def _driven_against_model(net, town) -> list[tuple[str, str, float, float]]:
    """(road, successor, driven length, model length) for every movement: driven is the edge
    plus the internal lanes of the connection taken; the model length is the road's geometry
    length, or the junctions' Euclidean distance for a road without one."""
    out = []
    for road in town.states:
        edge = net.getEdge(road)
        u, v = Road.parse(road)
        assert (edge.getFromNode().getID(), edge.getToNode().getID()) == (u, v)
        euclidean = math.dist(town.junctions[u], town.junctions[v])
        if road in town.geometry and len(town.geometry[road].shape) > 2:
            # Town01's outer streets: the road follows the street, far longer than its junctions' distance
            assert road in OUTER_ROADS and town.length(road) > euclidean + 100
        else:
            assert town.length(road) == pytest.approx(euclidean, abs=5e-4)  # the file keeps millimetres
        for successor, connections in edge.getOutgoing().items():
            if successor.getFunction():
                continue  # walking areas
            for connection in connections:
                out.append((road, successor.getID(), edge.getLength() + _internal_length(net, connection),
                            town.length(road)))
    assert len(out) == sum(len(town.successors(s)) for s in town.states)
    return out


def test_driven_lengths_within_five_percent_on_long_roads(tmp_path_factory):
    # The recipe's rule where roads are long against a junction (the pentagon: 240-820 m roads).
    town = load_town(PENTAGON_TOWN_PATH)
    net = sumolib.net.readNet(str(build_net(town, cache_dir=tmp_path_factory.mktemp("pentagon")).path),
                              withInternal=True)
    for road, successor, driven, length in _driven_against_model(net, town):
        assert abs(driven / length - 1) <= 0.05, (road, successor, driven, length)


# Town01's roads along the outer west and east streets: the town's geometry gives their course
# (three bends) and length (510.3 m and 444.2 m), and the net draws their edges along it.
OUTER_ROADS = ("A-E", "E-A", "H-L", "L-H")
# The geometry is a road's centre line; the vehicle lane runs right of it by the sidewalk and half
# a lane (1.5 + 1.5 m), and each junction cuts its corners (radius 2 m, corner detail 0: an internal
# lane is a straight chord). A right turn is driven on the inside of its corner: shorter than the
# centre line by the offset on each leg (6 m) plus the chord's cut; a left turn runs on the outside,
# where the chord takes back what the offset adds. Measured on Town01: every movement drives its
# road's model length within -9.6 m (right turns, H-I into I-G and J-K into K-D) and +0.9 m (left
# turns; L-H into H-F), on the outer streets within -7.9 m and +0.9 m. A straight edge would
# drive A-E and H-L about 190 m and 125 m short.
LANE_OFFSET_M = 1.5 + 1.5
RIGHT_TURN_CUT_M = 10.0
LEFT_TURN_EXCESS_M = 2.0


def test_driven_lengths_on_the_default_town(net, town):
    for road, successor, driven, length in _driven_against_model(net, town):
        assert -RIGHT_TURN_CUT_M <= driven - length <= LEFT_TURN_EXCESS_M, (road, successor, driven, length)


def test_outer_streets_are_drawn_along_their_geometry(net, town):
    for road in OUTER_ROADS:
        lane = net.getLane(f"{road}_1")
        # The lane's course bends like the street: its points stay within the lane offset (and the
        # junction's cut-off) of the geometry's bends, never on the straight junction line.
        for bend in town.geometry[road].shape[1:-1]:
            nearest = min(math.dist(bend, point) for point in lane.getShape())
            assert nearest <= 2 * LANE_OFFSET_M, (road, bend, nearest)
        assert lane.getLength() > town.length(road) - 2 * RIGHT_TURN_CUT_M, road


def test_a_bent_road_shapes_both_directions_and_straight_roads_stay_unshaped():
    from trustroute.networks.sumo_net import edge_shape, plain_xml
    from trustroute.networks.town import town_from_dict

    data = {"junctions": {"P": [0, 0], "Q": [300, 0], "R": [0, 300]},
            "roads": [["P", "Q"], ["Q", "R"], ["R", "P"]],
            "incidents": {r: "none" for r in ("P-Q", "Q-P", "Q-R", "R-Q", "R-P", "P-R")}}
    plain = town_from_dict(data, "plain.json")
    bent = town_from_dict({**data, "geometry": {
        "P-Q": {"shape": [[0, 0], [0, -100], [300, -100], [300, 0]], "length": 500},
        "Q-R": {"shape": [[300, 0], [0, 300]]}}}, "bent.json")
    assert edge_shape(bent, "P-Q") == ((0, 0), (0, -100), (300, -100), (300, 0))
    assert edge_shape(bent, "Q-P") == ((300, 0), (300, -100), (0, -100), (0, 0))  # mirrored
    assert edge_shape(bent, "Q-R") is None and edge_shape(plain, "P-Q") is None
    assert "shape=" not in plain_xml(plain)["edg"]
    assert 'shape="0.000,0.000 0.000,-100.000 300.000,-100.000 300.000,0.000"' in plain_xml(bent)["edg"]
    # Only the bent road's two edges differ from the straight town's plain XML.
    straight, shaped = plain_xml(plain)["edg"].splitlines(), plain_xml(bent)["edg"].splitlines()
    changed = [a for a, b in zip(straight, shaped, strict=True) if a != b]
    assert [line.split('"')[1] for line in changed] == ["P-Q", "Q-P"]


def test_movements_and_no_u_turns(net, town):
    for road in town.states:
        edge = net.getEdge(road)
        vehicle_targets = {nxt.getID() for nxt in edge.getOutgoing() if not nxt.getFunction()}
        assert vehicle_targets == set(town.successors(road)), road
        u, v = Road.parse(road)
        assert f"{v}-{u}" not in vehicle_targets  # no dead ends in the default town


def test_pedestrian_roads_have_crossings_at_both_ends(net, town):
    crossings = {}
    for edge in net.getEdges(withInternal=True):
        if edge.getFunction() == "crossing":
            crossings.setdefault(edge.getFromNode().getID(), []).append(
                frozenset(e.getID() for e in edge.getCrossingEdges()))
    for road in town.states:
        if town.incident(road) == "pedestrian":
            u, v = Road.parse(road)
            assert frozenset((road, f"{v}-{u}")) in crossings.get(u, []), road


def test_second_build_is_cache_hit(town, tmp_path):
    first = build_net(town, cache_dir=tmp_path)
    second = build_net(town, cache_dir=tmp_path)
    assert not first.cached and second.cached
    assert first.path == second.path and first.path.parent == tmp_path
    assert first.path.name.startswith(town.content_hash)
    assert first.connections == second.connections
    # no temp files left, and no lock in a folder of the user's: it stays in the cache (removing it
    # would race other builders)
    assert sorted(p.name for p in tmp_path.iterdir()) == [first.path.name]
    assert cache_entry_lock(first.path).is_file()


def test_truncated_cache_is_rebuilt(town, tmp_path):
    path = build_net(town, cache_dir=tmp_path).path
    path.write_text(path.read_text()[:500])
    again = build_net(town, cache_dir=tmp_path)
    assert not again.cached and again.edges == len(town.states)


def test_damaged_cache_entry_is_rebuilt_with_a_notice(town, tmp_path):
    path = build_net(town, cache_dir=tmp_path).path
    notices = []
    for damage in ("<net>\n</net>\n", "x" * 100 + "</net>", ""):
        path.write_text(damage)
        again = build_net(town, cache_dir=tmp_path, notice=notices.append)
        assert not again.cached and again.edges == len(town.states)
    assert len(notices) == 3 and all(path.name in n and "\n" not in n for n in notices)


def test_corrupt_net_gives_clear_error(tmp_path):
    bad = tmp_path / "bad.net.xml"
    bad.write_text("<net><edge id='x'")
    with pytest.raises(InputError, match="not a readable SUMO net"):
        net_counts(bad)
    other = tmp_path / "other.xml"
    other.write_text("<routes/>")
    with pytest.raises(InputError, match="not a SUMO net"):
        net_counts(other)


def test_missing_netconvert_is_input_error(town, tmp_path, monkeypatch):
    monkeypatch.setattr(sumolib, "checkBinary", lambda name, bindir=None: "netconvert-not-installed")
    monkeypatch.setenv("PATH", "")
    with pytest.raises(InputError, match="netconvert"):
        build_net(town, cache_dir=tmp_path)


def test_net_cli(tmp_path):
    from click.testing import CliRunner

    from trustroute.harness.cli import cli

    result = CliRunner().invoke(cli, ["net", "build", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    path = Path(result.output.splitlines()[0])
    assert path.is_file() and "36 edges, 12 junctions" in result.output and "built" in result.output
    result = CliRunner().invoke(cli, ["net", "build", "--out", str(tmp_path)])
    assert "cached" in result.output


def test_missing_binary_cli_exit_2(tmp_path):
    import subprocess
    import sys

    code = ("import sumolib; sumolib.checkBinary = lambda name, bindir=None: 'no-such-netconvert'\n"
            f"from harness.cli import main; main(['net', 'build', '--out', {str(tmp_path)!r}])")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            env={**os.environ, "PATH": ""})
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "netconvert" in result.stderr



def test_dead_end_allows_only_its_u_turn(tmp_path):
    from trustroute.networks.town import town_from_dict

    data = {"junctions": {"P": [0, 0], "Q": [300, 0], "R": [0, 300], "S": [-250, -250]},
            "roads": [["P", "Q"], ["Q", "R"], ["R", "P"], ["P", "S"]],
            "incidents": {r: "none" for r in ("P-Q", "Q-P", "Q-R", "R-Q", "R-P", "P-R", "P-S", "S-P")}}
    town = town_from_dict(data, "dead_end.json")
    net = sumolib.net.readNet(str(build_net(town, cache_dir=tmp_path).path))
    for road in town.states:
        targets = {nxt.getID() for nxt in net.getEdge(road).getOutgoing() if not nxt.getFunction()}
        assert targets == set(town.successors(road)), road
    assert {nxt.getID() for nxt in net.getEdge("P-S").getOutgoing()} == {"S-P"}
