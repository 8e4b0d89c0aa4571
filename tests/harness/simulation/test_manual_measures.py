"""The manual-driving measures on constructed traces, against hand computations."""

from __future__ import annotations

import math

import pytest

from trustroute.harness.simulation.manual_measures import (
    Sample,
    episode_measures,
    lateral_sd,
    max_deceleration,
    min_ttc,
    oncoming_seconds,
    signed_offset,
    takeover_measures,
    takeover_reaction,
    ttc_ahead,
)


def trace(*rows):
    return [Sample(t, lateral, speed, ttc) for t, lateral, speed, ttc in rows]


def test_the_reaction_is_from_the_incident_in_view_to_the_takeover():
    assert takeover_reaction(12.5, 14.25) == 1.75
    assert math.isnan(takeover_reaction(math.nan, 14.0))      # never in view
    assert math.isnan(takeover_reaction(12.0, math.nan))      # no takeover
    assert math.isnan(takeover_reaction(15.0, 14.0))          # taken over before it came into view


def test_lateral_sd_is_the_population_standard_deviation_of_the_lateral_position():
    # laterals 0, 1, 2, 3, 4: mean 2, squared deviations 4 + 1 + 0 + 1 + 4 = 10, / 5 = 2
    samples = trace(*((t, float(t), 8.0, math.inf) for t in range(5)))
    assert lateral_sd(samples) == pytest.approx(math.sqrt(2.0))
    assert lateral_sd(trace((0.0, 1.5, 8.0, math.inf))) == 0.0
    assert math.isnan(lateral_sd([]))


def test_the_largest_deceleration_is_the_steepest_drop_between_samples():
    # 10 -> 9 in 0.1 s (10 m/s²), 9 -> 8.5 in 0.1 s (5), 8.5 -> 9 (speeding up)
    samples = trace((0.0, 0, 10.0, 1), (0.1, 0, 9.0, 1), (0.2, 0, 8.5, 1), (0.3, 0, 9.0, 1))
    assert max_deceleration(samples) == pytest.approx(10.0)
    assert max_deceleration(trace((0.0, 0, 5.0, 1), (1.0, 0, 6.0, 1))) == 0.0
    assert min_ttc(samples) == 1 and min_ttc([]) == math.inf


def test_time_in_the_oncoming_lane_counts_each_stay_within_the_takeover():
    events = [{"t": 2.0, "type": "oncoming"}, {"t": 5.5, "type": "own_lane"},
              {"t": 7.0, "type": "oncoming"}, {"t": 8.0, "type": "off_road"},
              {"t": 9.0, "type": "collision"}, {"t": 11.0, "type": "oncoming"}]
    # 3.5 s, then 1 s, then 11 -> 12 (still there at the end): 5.5 s
    assert oncoming_seconds(events, 0.0, 12.0) == pytest.approx(5.5)
    assert oncoming_seconds(events, 3.0, 7.5) == pytest.approx(2.5 + 0.5)
    measures = takeover_measures(trace((0.0, 0.0, 8.0, 4.0), (12.0, 2.0, 6.0, 2.5)), events, 0.0, 12.0)
    assert measures == {"lateral_sd": 1.0, "manual_min_ttc": 2.5,
                        "manual_max_deceleration": pytest.approx(2.0 / 12.0),
                        "oncoming_seconds": pytest.approx(5.5), "road_departures": 1, "collisions": 1}


def test_the_time_to_collision_is_with_what_is_in_the_cars_path():
    # heading north at 10 m/s, front at (0, 0); a truck 12 m long, 2.5 m wide, coming south at 5 m/s
    # with its front at (0, 30): its nearer end is its front, 30 m ahead: 30 / (10 + 5) = 2 s
    truck = (0.0, 30.0, 180.0, 5.0, 12.0, 2.5)
    assert ttc_ahead(0.0, 0.0, 0.0, 10.0, 1.8, [truck]) == pytest.approx(2.0)
    # a car ahead going the same way at 4 m/s, its back 20 m ahead (front at 24.5): 20 / 6
    car = (0.0, 24.5, 0.0, 4.0, 4.5, 1.8)
    assert ttc_ahead(0.0, 0.0, 0.0, 10.0, 1.8, [car]) == pytest.approx(20.0 / 6.0)
    # beside the path (3 m to the left, the widths' half sum 2.15 m), behind, or faster: none
    aside = (-3.0, 30.0, 180.0, 5.0, 12.0, 2.5)
    behind = (0.0, -10.0, 0.0, 4.0, 4.5, 1.8)
    faster = (0.0, 24.5, 0.0, 12.0, 4.5, 1.8)
    assert ttc_ahead(0.0, 0.0, 0.0, 10.0, 1.8, [aside, behind, faster]) == math.inf


def test_the_lateral_offset_is_signed_left_positive():
    lane = [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)]   # east, then north
    assert signed_offset(lane, 5.0, 1.5) == pytest.approx(1.5)     # north of an eastbound line: left
    assert signed_offset(lane, 5.0, -0.5) == pytest.approx(-0.5)
    assert signed_offset(lane, 11.0, 6.0) == pytest.approx(-1.0)   # east of a northbound line: right


def test_an_episodes_measures_gather_its_takeovers():
    nan = math.nan
    rows = [  # a takeover by wheel, one assisted (the reaction only), a road without a takeover
        {"takeover": True, "takeover_reaction": 1.0, "lateral_sd": 0.3, "manual_min_ttc": 2.0,
         "manual_max_deceleration": 4.0, "oncoming_seconds": 3.0, "road_departures": 1, "collisions": 0},
        {"takeover": True, "takeover_reaction": 2.0, "lateral_sd": None, "manual_min_ttc": None,
         "manual_max_deceleration": None, "oncoming_seconds": None, "road_departures": None,
         "collisions": None},
        {"takeover": False, "takeover_reaction": nan, "lateral_sd": None},
    ]
    assert episode_measures(rows) == {"mean_takeover_reaction": 1.5, "mean_lateral_sd": 0.3,
                                      "manual_min_ttc": 2.0, "manual_max_deceleration": 4.0,
                                      "oncoming_seconds": 3.0, "road_departures": 1, "collisions": 0}
    assert set(episode_measures(rows[1:]).values()) == {2.0, None}
    assert set(episode_measures([]).values()) == {None}
