"""The directed road "U-V" (networks/road.py): parsed and written in one place."""

from __future__ import annotations

import pytest

from trustroute.networks.road import Road
from trustroute.networks.town import load_town


def test_parse_and_format_round_trip_on_every_packaged_road():
    for name in ("town01_carla", "pentagon"):
        town = load_town(name)
        for road_id in town.states:
            road = Road.parse(road_id)
            assert road.id == str(road) == f"{road}" == road_id
            assert road.from_junction in town.junctions and road.to_junction in town.junctions
            assert Road.parse(road.reverse.id).reverse == road


def test_the_parts_name_the_junctions_left_and_entered():
    road = Road.parse("A_1-B2")
    assert (road.from_junction, road.to_junction) == ("A_1", "B2")
    assert road.reverse == Road("B2", "A_1")
    u, v = road
    assert (u, v) == ("A_1", "B2")


@pytest.mark.parametrize("text", ["A", "A-", "-B", "A-B-C", "", ":A_5"])
def test_a_string_that_is_not_a_road_id_is_refused(text):
    with pytest.raises(ValueError, match="not a directed road id"):
        Road.parse(text)
    assert Road.parse_or_none(text) is None
