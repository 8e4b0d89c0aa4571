"""The default town is the Town01 town file derived from the authors' tables
(networks/data/PROVENANCE.md); its trust-free routes beside the authors' preset routes are
tested in tests/policies/routing/test_free_vs_authors_routes.py."""

from __future__ import annotations

import json

from trustroute.analysis.carla_study.town01 import load_carla_tables, town01_town_dict
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
