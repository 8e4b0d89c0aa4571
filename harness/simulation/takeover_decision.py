"""Where takeovers are decided in a SUMO episode, and switched on and off.

A synthetic driver decides once per road, h ~ P(takeover | θ, incident) at its trust then (its
`decides_takeover`, drawn by participants/driver_step.py `draw_takeovers`), at the first of:

- the incident's object coming within `VIEW_DISTANCE` of the ego (`in_view`);
- the ego entering a road whose incident put nothing on it;
- the road's observation closing with the object never in view (the model decides on every road).

A person in a live study takes over and hands back whenever they choose (`apply_request`, asked
every step, on the start road too). A takeover switches the ego to the manual driving style
(driving_style.py) until the road's commit point, where `hand_back_at_road_end` returns it to the
autopilot. The start road is not observed: a takeover on it counts for the first road after it
(`count_for_first_road`). The model engine
draws the same decision in participants/driver_step.py `draw_step`.
"""

from __future__ import annotations

import math
from typing import Protocol

from trustroute.harness.simulation.driving_style import AUTOPILOT, hand_back, take_over
from trustroute.harness.simulation.sumo_start import Sumo

VIEW_DISTANCE = 80.0   # metres: an incident object this close to the ego is in view


class Driver(Protocol):
    def decides_takeover(self, incident: str) -> bool: ...


class RoadTakeover(Protocol):
    """A road's takeover fields, as the episode's road record keeps them."""

    decided: bool
    took_over: bool
    takeover_start: float
    takeover_end: float


def in_view(distance: float) -> bool:
    return distance <= VIEW_DISTANCE


def decide(sumo: Sumo, vehicle_id: str, road: RoadTakeover, driver: Driver, incident: str, now: float,
           mode: str) -> str:
    """The synthetic driver's decision on `road`; returns the control mode after it."""
    road.decided = True
    road.took_over = bool(driver.decides_takeover(incident))
    if not road.took_over:
        return mode
    road.takeover_start = now
    return take_over(sumo, vehicle_id)


def apply_request(sumo: Sumo, vehicle_id: str, road: RoadTakeover, request: bool | None, mode: str,
                  now: float) -> str:
    """A person's takeover (True) or hand-back (False) on the open road, None for neither; returns
    the control mode after it. A takeover also settles the road's decision: it counts as taken over."""
    if request is True and mode == AUTOPILOT.name:
        road.decided = road.took_over = True
        if math.isnan(road.takeover_start):
            road.takeover_start = now
        return take_over(sumo, vehicle_id)
    if request is False and mode != AUTOPILOT.name:
        road.takeover_end = now
        return hand_back(sumo, vehicle_id)
    return mode


def count_for_first_road(start: RoadTakeover, first: RoadTakeover) -> None:
    """A person's takeover on the start road, which has no observation of its own (model position
    0), counted for the first road observed after it (`first`, begun at the start road's commit
    point), as a takeover in a road's closing step counts for the next road: taken over from the
    takeover's time until its hand-back (the person's, or the start road's commit point's)."""
    if start.took_over:
        first.decided = first.took_over = True
        first.takeover_start, first.takeover_end = start.takeover_start, start.takeover_end


def hand_back_at_road_end(sumo: Sumo, vehicle_id: str, road: RoadTakeover, mode: str, now: float) -> str:
    """Back to the autopilot at the road's commit point, before the next junction."""
    if mode == AUTOPILOT.name:
        return mode
    road.takeover_end = now
    return hand_back(sumo, vehicle_id)
