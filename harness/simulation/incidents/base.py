"""The one interface every incident kind implements, and the scene an incident is injected into.

An incident belongs to a directed road. `inject` is called when the ego commits to that road
(the route is extended one road ahead), so the SUMO objects are in place (or timed to arrive)
when the ego enters it; `step` runs every simulation step while the incident is live and may
insert objects whose timing depends on the ego (a late pedestrian, an oncoming truck);
`measure` feeds the road's PerformanceMonitor with what only the incident knows (head-on gaps,
the distance to a person on the crossing); `is_passed` says when the ego is past it; `remove`
takes every SUMO object out (idempotent). Kinds live one per module (pedestrian.py,
obstacle.py, truck.py) and are chosen by name in `harness.simulation.incidents.inject`. Every random draw
of a scene comes from `Scene.rng`, the episode's seeded scene generator (docs/scenes.md).
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import numpy as np

from trustroute.harness.simulation.sumo_start import net_fact
from trustroute.networks.road import Road

NOT_ON_THE_NET = 1e8   # metres: beyond any town; SUMO's invalid position is about -1.07e9


class EgoState(NamedTuple):
    """The ego as the runner read it this step (one subscription); a NamedTuple: built every step."""

    time: float
    road: str          # edge id; internal junction edges start with ':'
    lane_position: float
    x: float
    y: float
    speed: float
    lane: str = ""     # lane id; while overtaking it is the opposite road's lane
    angle: float = 0.0  # heading, degrees clockwise from north (SUMO's convention)
    acceleration: float = 0.0   # m/s² in the last step (negative: braking)


@dataclass(frozen=True)
class Scene:
    """Where an incident is injected: its road, the road's length, and unique id prefix.

    ego_distance: metres the ego still has to drive to the start of `road` when the incident is
    injected (its commit point on the previous road plus the junction); incidents time their
    objects with it. rng: the episode's scene generator; overrides: fixed values for a scene's
    draws (tests, screenshots), keyed by the draw's name in the kind's module.
    """

    road: str
    reverse_road: str | None   # the opposite directed road (pedestrians walk from its sidewalk)
    road_length: float
    prefix: str                # unique per episode and road, e.g. "inc3"
    ego_id: str
    time: float
    ego_distance: float = 40.0
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    overrides: dict = field(default_factory=dict)
    road_speed: float = 13.89
    step_length: float = 0.5   # seconds per simulation step
    observed_length: float | None = None   # metres of the road watched before the incident is
                                           # removed (the ego's commit point); None: all of it
    # On an imported town's own net (harness/simulation/real_roads.py) `road` is one SUMO edge of
    # the model road: its driving lane, the reverse edge's nearest lane, whether SUMO may overtake
    # through the opposite lane there, and the edge's end and start junctions. The defaults are a net built
    # by `trustroute net build`: lane 1 beside the sidewalk, opposite lanes declared, "U-V" ids.
    lane: int = 1
    lanes: int = 1             # lanes of the road's direction open to cars
    reverse_lane: int = 1
    overtake: bool = True
    end_junction: str | None = None
    start_junction: str | None = None

    @property
    def ends_at(self) -> str:
        """The junction where the scene's road ends."""
        return self.end_junction if self.end_junction is not None else Road.parse(self.road).to_junction

    @property
    def watched(self) -> float:
        """Metres into the road until which the incident is in the simulation."""
        return self.road_length if self.observed_length is None else max(0.0, self.observed_length)

    def draw(self, name: str, sample):
        """A scene parameter: the override if given, else `sample(rng)` (always drawn, so the
        generator's stream does not depend on which values are overridden)."""
        value = sample(self.rng)
        return self.overrides.get(name, value)


class Incident(Protocol):
    kind: str
    road: str
    sumo_ids: tuple[str, ...]

    def position(self, sumo) -> tuple[float, float] | None:
        """Where the incident object is now (None when it is gone or not yet in the simulation)."""

    def step(self, sumo, ego: EgoState) -> None:
        """Per-step behaviour (e.g. a pedestrian stepping onto the crossing late)."""

    def measure(self, sumo, ego: EgoState, monitor) -> None:
        """Add this step's incident-specific measures to the road's PerformanceMonitor."""

    def is_passed(self, sumo, ego: EgoState) -> bool:
        """True once the ego is past the incident."""

    def done(self) -> bool:
        """True once `step` and `measure` can do nothing more (what acts or is measured has left
        the simulation, or never acts): once the ego has passed it too, the episode stops
        stepping it (nothing then changes until the road's end removes it)."""

    def remove(self, sumo) -> None:
        """Take every SUMO object of the incident out of the simulation (safe to call twice)."""

    def details(self) -> str:
        """The scene's drawn parameters, as `key=value` pairs for the incidents table."""


# The incident kinds share these.

@dataclass(frozen=True)
class VehicleType:
    """A SUMO type copied from `base` (SUMO's default car, or its default person): each attribute
    given replaces the default's (None keeps it). Imperfection and speed deviation are 0 unless
    given, so no incident object draws from SUMO's own random streams (every draw of an episode
    comes from its seeded Generator, which is what lets episodes share one simulation: sumo_start)."""

    type_id: str
    color: tuple[int, int, int, int]
    vehicle_class: str | None = None
    shape_class: str | None = None
    length: float | None = None
    width: float | None = None
    max_speed: float | None = None
    accel: float | None = None
    imperfection: float | None = 0.0
    speed_deviation: float | None = 0.0
    base: str = "DEFAULT_VEHTYPE"


def define_vehicle_type(sumo, vehicle_type: VehicleType) -> None:
    """Add `vehicle_type` to the simulation: the base type's copy, then the attributes given."""
    types, type_id = sumo.vehicletype, vehicle_type.type_id
    types.copy(vehicle_type.base, type_id)
    setters = ((types.setVehicleClass, vehicle_type.vehicle_class),
               (types.setShapeClass, vehicle_type.shape_class),
               (types.setLength, vehicle_type.length),
               (types.setWidth, vehicle_type.width),
               (types.setMaxSpeed, vehicle_type.max_speed),
               (types.setAccel, vehicle_type.accel),
               (types.setImperfection, vehicle_type.imperfection),
               (types.setSpeedDeviation, vehicle_type.speed_deviation),
               (types.setColor, vehicle_type.color))
    for setter, value in setters:
        if value is not None:
            setter(type_id, value)


def lane_length(sumo, lane: str) -> float:
    """The lane's length, read once per started simulation (sumo_start.net_fact)."""
    return net_fact(("lane length", lane), lambda: sumo.lane.getLength(lane))


def vehicle_on_the_net(sumo, vehicle_id: str) -> tuple[float, float] | None:
    """Where the vehicle is, or None while it is added but not yet inserted (SUMO's invalid
    position); SUMO's TraCIException when it is not (or no longer) in the simulation."""
    x, y = sumo.vehicle.getPosition(vehicle_id)
    return None if abs(x) > NOT_ON_THE_NET or abs(y) > NOT_ON_THE_NET else (x, y)


def vehicle_position(sumo, vehicle_id: str) -> tuple[float, float] | None:
    """Where the incident's vehicle is, or None when it is not in the simulation."""
    try:
        return vehicle_on_the_net(sumo, vehicle_id)
    except sumo.TraCIException:
        return None


def remove_vehicle(sumo, vehicle_id: str) -> None:
    """Take the vehicle out; also reaches one still waiting for insertion, and one already gone
    raises inside SUMO, which is fine (removal is idempotent)."""
    with contextlib.suppress(sumo.TraCIException):
        sumo.vehicle.remove(vehicle_id)


def park_vehicle(sumo, vehicle_id: str, route_id: str, road: str, position: float, type_id: str,
                 lane: int = 1, duration: float = 1e9) -> None:
    """A vehicle parked in the road's driving lane `lane`: a stop whose range already holds the
    vehicle's front, so it does not move before `duration` seconds (by default never, and it never
    leaves by itself). (A stop rather than a speed held at 0: SUMO's drivers treat a stopped
    vehicle as one to overtake.)"""
    sumo.route.add(route_id, [road])
    sumo.vehicle.add(vehicle_id, route_id, typeID=type_id, depart="now", departLane=str(lane),
                     departPos=f"{position:.2f}", departSpeed="0")
    sumo.vehicle.setStop(vehicle_id, road, pos=position + 0.05, laneIndex=lane, duration=duration,
                         startPos=position - 1.0)
    sumo.vehicle.setLaneChangeMode(vehicle_id, 0)


def head_on_ttc(sumo, ego: EgoState, vehicle_id: str) -> float:
    """Time to a head-on collision with `vehicle_id` when both are in one lane driving towards
    each other (one of them overtaking through the oncoming lane); inf otherwise or when gone."""
    try:
        lane = sumo.vehicle.getLaneID(vehicle_id)
    except sumo.TraCIException:
        return math.inf
    if lane != ego.lane:
        return math.inf
    x, y = sumo.vehicle.getPosition(vehicle_id)
    angle = math.radians(sumo.vehicle.getAngle(vehicle_id))
    ego_angle = math.radians(ego.angle)
    # Towards each other: opposite headings, and the vehicle's heading points at the ego.
    opposite = math.cos(angle - ego_angle) < 0
    towards = (ego.x - x) * math.sin(angle) + (ego.y - y) * math.cos(angle)
    if not opposite or towards <= 0:
        return math.inf
    closing = ego.speed + sumo.vehicle.getSpeed(vehicle_id)
    gap = math.dist((x, y), (ego.x, ego.y))   # front to front: both fronts face each other
    return gap / closing if closing > 0 else math.inf
