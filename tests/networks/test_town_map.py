"""The map frame of a town (extent, marker unit) and points along road shapes."""

from __future__ import annotations

import pytest

from trustroute.networks.town import town_from_dict
from trustroute.networks.town_map import MAX_UNIT, MIN_UNIT, map_frame, names_every_junction, point_along


def test_point_along_a_polyline_and_to_its_right():
    assert point_along([(0, 0), (10, 0), (10, 10)], 0.5) == pytest.approx((10.0, 0.0))
    assert point_along([(0, 0), (10, 0), (10, 10)], 0.75) == pytest.approx((10.0, 5.0))
    assert point_along([(0, 0), (10, 0)], 0.5, 2.0) == pytest.approx((5.0, -2.0))  # east: right is south
    assert point_along([(0, 0), (0, 10)], 1.0, 1.0) == pytest.approx((1.0, 10.0))  # north: right is east
    assert point_along([(3, 4), (3, 4)], 0.5) == pytest.approx((3.0, 4.0))


def _grid(n: int, spacing: float) -> dict:
    names = [f"J{i}_{j}" for i in range(n) for j in range(n)]
    junctions = {f"J{i}_{j}": [i * spacing, j * spacing] for i in range(n) for j in range(n)}
    roads = [[f"J{i}_{j}", f"J{i + 1}_{j}"] for i in range(n - 1) for j in range(n)]
    roads += [[f"J{i}_{j}", f"J{i}_{j + 1}"] for i in range(n) for j in range(n - 1)]
    incidents = {f"{u}-{v}": "none" for a, b in roads for u, v in ((a, b), (b, a))}
    assert len(names) == n * n
    return {"junctions": junctions, "roads": roads, "incidents": incidents}


def test_the_unit_grows_with_the_town_and_stays_bounded(town):
    small = map_frame(town)
    assert 2.0 < small.unit < 4.0 and small.x_min < small.x_max and small.y_min < small.y_max
    city = town_from_dict(_grid(10, 250.0), "city.json")
    assert map_frame(city).unit == pytest.approx(map_frame(city).diagonal / 150.0)
    assert map_frame(city).unit > 5 * small.unit
    assert map_frame(town_from_dict(_grid(3, 20.0), "tiny.json")).unit == MIN_UNIT
    assert map_frame(town_from_dict(_grid(3, 50_000.0), "huge.json")).unit == MAX_UNIT
    assert names_every_junction(town) and not names_every_junction(city)


def test_the_frame_holds_the_road_shapes(town):
    data = _grid(2, 100.0)
    data["geometry"] = {"J0_0-J1_0": {"shape": [[0, 0], [50, -80], [100, 0]]}}
    frame = map_frame(town_from_dict(data, "bent.json"))
    assert frame.y_min == -80.0
