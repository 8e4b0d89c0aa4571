"""The one interface every incident kind implements, and the scene an incident is injected into.

An incident belongs to a directed road. `inject` is called when the ego commits to that road
(the route is extended one road ahead), so the SUMO objects are in place by the time the ego
enters it; `step` runs every simulation step while the incident is live; `is_passed` says when
the ego is past it; `remove` takes every SUMO object out (idempotent). Kinds live one per module
(pedestrian.py, obstacle.py, truck.py) and are chosen by name in `harness.incidents.inject`.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import NamedTuple, Protocol


class EgoState(NamedTuple):
    """The ego as the runner read it this step (one subscription); a NamedTuple: built every step."""

    time: float
    road: str          # edge id; internal junction edges start with ':'
    lane_position: float
    x: float
    y: float
    speed: float


@dataclass(frozen=True)
class Scene:
    """Where an incident is injected: its road, the road's length, and unique id prefix."""

    road: str
    reverse_road: str | None   # the opposite directed road (pedestrians walk from its sidewalk)
    road_length: float
    prefix: str                # unique per episode and road, e.g. "inc3"
    ego_id: str
    time: float


class Incident(Protocol):
    kind: str
    road: str
    sumo_ids: tuple[str, ...]

    def position(self, sumo) -> tuple[float, float] | None:
        """Where the incident object is now (None when it is gone from the simulation)."""

    def step(self, sumo, ego: EgoState) -> None:
        """Per-step behaviour (e.g. the obstacle clears once the ego has waited behind it)."""

    def is_passed(self, sumo, ego: EgoState) -> bool:
        """True once the ego is past the incident."""

    def remove(self, sumo) -> None:
        """Take every SUMO object of the incident out of the simulation (safe to call twice)."""


# The vehicle-backed kinds (obstacle, truck) share these: one SUMO vehicle per incident.

def vehicle_present(sumo, vehicle_id: str) -> bool:
    return vehicle_id in sumo.vehicle.getIDList()


def vehicle_position(sumo, vehicle_id: str) -> tuple[float, float] | None:
    """Where the incident's vehicle is, or None once it has left the simulation."""
    return tuple(sumo.vehicle.getPosition(vehicle_id)) if vehicle_present(sumo, vehicle_id) else None


def remove_vehicle(sumo, vehicle_id: str) -> None:
    """Take the vehicle out; also reaches one still waiting for insertion, and one already gone
    raises inside SUMO, which is fine (removal is idempotent)."""
    with contextlib.suppress(sumo.TraCIException):
        sumo.vehicle.remove(vehicle_id)
