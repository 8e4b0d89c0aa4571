"""The Town01 town file derived from the authors' tables, and its trust-free routes beside the
authors' preset baseline routes (docs/real_study.md, "Town01 geometry")."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from trustroute.analysis.carla_tables import load_carla_tables, town01_town_dict
from trustroute.networks.town import DEFAULT_TOWN_PATH, load_town

TOWN01 = DEFAULT_TOWN_PATH.parent / "town01_carla.json"


def test_packaged_town01_is_the_derivation_from_the_tables():
    derived = town01_town_dict(load_carla_tables(), json.loads(Path(DEFAULT_TOWN_PATH).read_text()))
    assert derived["junctions"] == json.loads(TOWN01.read_text())["junctions"]
    town = load_town(TOWN01)
    # Town01 is a grid: A-E on the west street, H-L on the east street, F and G between
    west = [town.junctions[j][0] for j in "ABCDE"]
    east = [town.junctions[j][0] for j in "HIJKL"]
    assert max(west) - min(west) < 10 and max(east) - min(east) < 10 and min(east) - max(west) > 200


@pytest.mark.parametrize(
    ("trial", "ratio_at_most"),
    [(1, 1.01), (2, 1.03)],  # measured: 559.7/556.4 m and 1050.1/1026.9 m
)
def test_preset_baseline_routes_nearly_tie_the_spec_shortest_routes_on_town01(trial, ratio_at_most):
    from trustroute.harness.study.config import PACKAGED_SPECS
    from trustroute.policies.logic.spec import load_spec
    from trustroute.policies.routing.free import baseline_route

    tables, town = load_carla_tables(), load_town(TOWN01)
    spec = load_spec(PACKAGED_SPECS / f"{tables.trials[trial]['spec']}.toml", town)
    preset = [
        tables.road_of_state[s] for s in [tables.trials[trial]["start"], *tables.baseline_routes[trial]]
    ]
    assert preset[0] == spec.start
    shortest = baseline_route(town, spec)
    assert town.route_length(preset) >= town.route_length(shortest) - 1e-9
    assert town.route_length(preset) / town.route_length(shortest) <= ratio_at_most
