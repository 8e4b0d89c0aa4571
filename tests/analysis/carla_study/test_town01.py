"""The default town is the Town01 town file derived from the authors' tables
(networks/data/PROVENANCE.md), its road shapes and lengths checked against their spawn points,
arrival points and driven positions; its trust-free routes beside the authors' preset routes are
tested in tests/policies/routing/test_free_vs_authors_routes.py."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from trustroute.analysis.carla_study.town01 import (
    ARRIVAL_RADIUS_M,
    load_carla_tables,
    outer_streets,
    town01_town_dict,
)
from trustroute.networks.road_lookup import distance_to_road
from trustroute.networks.town import DEFAULT_TOWN_PATH, PENTAGON_TOWN_PATH, load_town


def test_the_default_town_is_the_derivation_from_the_authors_tables():
    derived = town01_town_dict(load_carla_tables())
    assert derived == json.loads(DEFAULT_TOWN_PATH.read_text())
    town = load_town()
    # Town01 is a grid: A-E on the west street, H-L on the east street, F and G between
    west = [town.junctions[j][0] for j in "ABCDE"]
    east = [town.junctions[j][0] for j in "HIJKL"]
    assert max(west) - min(west) < 10 and max(east) - min(east) < 10 and min(east) - max(west) > 200


def test_the_pentagon_has_the_same_roads_and_incidents_on_other_coordinates():
    town01, pentagon = load_town(), load_town(PENTAGON_TOWN_PATH)
    assert sorted(map(sorted, town01.roads)) == sorted(map(sorted, pentagon.roads))
    assert town01.incidents == pentagon.incidents
    assert town01.junctions != pentagon.junctions and town01.content_hash != pentagon.content_hash


# -- road shapes and lengths against the authors' tables ----------------------------------------------

def _on_town_plane(point) -> np.ndarray:
    """A CARLA (x, y) of the authors' tables in the town's frame (y negated)."""
    return np.array([point[0], -point[1]])


@pytest.mark.parametrize(("road", "side"), [("A-E", "west"), ("E-A", "west"), ("H-L", "east"),
                                            ("L-H", "east")])
def test_the_outer_roads_run_along_the_outer_streets(road, side):
    tables, town = load_carla_tables(), load_town()
    streets = outer_streets(tables)
    u, v = road.split("-")
    arrival = _on_town_plane(tables.arrival_point[tables.state_of_road[road]])
    # The evidence: the road arrives from the outer side of its junction, not along the inner street.
    outward = -1 if side == "west" else 1
    assert outward * (arrival[0] - town.junctions[v][0]) > 10
    # Every spawn point of the outer street between the north and south streets lies on the road
    # (lanes are 1.75 m from the centre line), and the road passes through its arrival disc.
    lane_points = [p for p in tables.spawn_points
                   if abs(p[0] - streets[side]) < 3 and streets["north"] + 10 < p[1] < streets["south"] - 10]
    assert len(lane_points) >= 15
    assert max(distance_to_road(town, road, _on_town_plane(p)) for p in lane_points) < 2.5
    assert distance_to_road(town, road, arrival) < ARRIVAL_RADIUS_M
    # The length: out along the junction's street, the outer street's full length, back in.
    along_streets = (abs(town.junctions[u][0] - streets[side]) + (streets["south"] - streets["north"])
                     + abs(town.junctions[v][0] - streets[side]))
    assert town.length(road) == pytest.approx(along_streets, rel=0.005)
    straight = math.dist(town.junctions[u], town.junctions[v])
    assert town.length(road) > straight + 2 * 50  # the 319 m straight line missed both detours


def test_the_outer_street_lengths():
    town = load_town()
    assert town.length("A-E") == town.length("E-A") == pytest.approx(510.28, abs=0.01)
    assert town.length("H-L") == town.length("L-H") == pytest.approx(444.19, abs=0.01)


def test_every_other_road_is_straight_between_its_junctions():
    town = load_town()
    for road in town.states:
        if road in ("A-E", "E-A", "H-L", "L-H"):
            continue
        u, v = road.split("-")
        assert len(town.geometry[road].shape) == 2
        assert town.length(road) == pytest.approx(math.dist(town.junctions[u], town.junctions[v]), abs=1e-3)


def test_driven_lengths_in_the_authors_logs_match_the_road_lengths():
    """The released study's positions (every 25th tick of their logs) between a road's entry and
    its arrival test: the median over drives is the road's length to within the sampling (up to
    1.25 s at each end) and the arrival discs' offsets from the junction centres."""
    study = Path("analysis/data/real_study/study")
    kinematics = pd.read_parquet(study / "kinematics.parquet")
    roads = pd.read_parquet(study / "roads.parquet").merge(
        pd.read_parquet(study / "real_roads.parquet")[["episode_id", "index", "arrived"]],
        on=["episode_id", "index"])
    town = load_town()
    driven: dict[str, list[float]] = {}
    for episode, positions in kinematics.groupby("episode_id"):
        for row in roads[(roads.episode_id == episode) & (roads["index"] > 0) & roads.arrived].itertuples():
            stretch = positions[(positions.time >= row.sim_time_in) & (positions.time <= row.sim_time_out)]
            points = stretch[["x", "y"]].to_numpy()
            if len(points) >= 3:
                driven.setdefault(row.directed_road, []).append(
                    float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum()))
    checked = {road: float(np.median(lengths)) for road, lengths in driven.items() if len(lengths) >= 3}
    assert len(checked) >= 18
    for road, length in checked.items():
        assert abs(length - town.length(road)) < 15.0, (road, length, town.length(road))
