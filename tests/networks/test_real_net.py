"""An imported town's roads as edges of its own net: the edge lists of the town, the lanes an
incident uses, the opposite lanes netconvert declares, and the net's hash checked."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from tests.networks.sumo_nets import WHEEL_NODES, WHEEL_ROADS, build_plain_net
from trustroute.core.errors import InputError
from trustroute.networks.real_net import is_imported, road_edges, town_net_file
from trustroute.networks.sumo_net import find_binary
from trustroute.networks.town import load_town
from trustroute.networks.town_import import import_town


def imported_wheel(folder: Path, opposites: bool, sidewalks: bool = False):
    net = build_plain_net(folder, "wheel", WHEEL_NODES, WHEEL_ROADS)
    options = (["--opposites.guess", "true"] if opposites else []) + (
        ["--sidewalks.guess", "true"] if sidewalks else [])
    if options:
        subprocess.run([find_binary("netconvert"), "-s", str(net), *options, "-o", str(net), "--no-warnings"],
                       check=True, capture_output=True)
    import_town(net, folder / "town.json")
    return load_town(folder / "town.json"), net


@pytest.mark.parametrize("opposites", [True, False])
def test_the_roads_are_their_edges_with_the_opposite_lane_where_declared(tmp_path, opposites):
    town, net = imported_wheel(tmp_path, opposites)
    assert is_imported(town) and town_net_file(town) == net
    roads = road_edges(town, net)
    assert set(roads) == set(town.states)
    for road, value in roads.items():
        assert value.ids == town.geometry[road].edges
        assert value.length == pytest.approx(town.length(road), abs=0.05)
        (edge,) = value.edges
        u, v = road.split("-")
        assert (edge.start_junction, edge.end_junction) == (u, v)
        assert edge.reverse_edge == f"{v}_{u}" and edge.overtake is opposites
        assert edge.passenger_lanes == 1 and not edge.sidewalk


def test_sidewalks_are_seen_on_both_directions(tmp_path):
    town, net = imported_wheel(tmp_path, opposites=False, sidewalks=True)
    edge = road_edges(town, net)["a-b"].edges[0]
    assert edge.sidewalk and edge.reverse_sidewalk
    assert edge.driving_lane == 1     # lane 0 is the sidewalk


def test_a_changed_or_missing_net_is_an_input_error(tmp_path):
    town, net = imported_wheel(tmp_path, opposites=False)
    net.write_bytes(net.read_bytes() + b"\n")
    with pytest.raises(InputError, match="has changed since the town was imported") as error:
        town_net_file(town)
    assert "re-import" in str(error.value) and str(net) in str(error.value)
    net.unlink()
    with pytest.raises(InputError, match="does not exist"):
        town_net_file(town)


def test_a_road_without_edges_cannot_be_driven(tmp_path):
    _, net = imported_wheel(tmp_path, opposites=False)
    document = json.loads((tmp_path / "town.json").read_text())
    del document["geometry"]["a-b"]["edges"]
    (tmp_path / "bare.json").write_text(json.dumps(document))
    town = load_town(tmp_path / "bare.json")
    with pytest.raises(InputError, match="lists no SUMO edges"):
        road_edges(town, net)
