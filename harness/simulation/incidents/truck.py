"""Truck incident: an oncoming truck in the neighbouring lane, timed to meet the ego on its road.

The truck drives the opposite directed road at `oncoming.TRUCK_SPEED` and is scheduled to pass
the ego at a drawn fraction of the stretch watched before the ego's commit point
(`MEET_RANGE` of `Scene.watched`), assuming the ego drives at free speed.
With probability `P_PARKED` a car is parked in the truck's own lane shortly before that point
(`PARKED_BEFORE_MEETING`, drawn): the truck then overtakes it through the ego's lane, with
SUMO's own opposite-direction overtaking and gap acceptance, and the ego has to react to a
truck in its lane (only where the net has opposite lanes, Scene.overtake: elsewhere no car is
parked). The incident is passed once the two have met. Draws: docs/scenes.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from trustroute.harness.simulation.incidents.base import (
    EgoState,
    Scene,
    VehicleType,
    define_vehicle_type,
    lane_length,
    park_vehicle,
    remove_vehicle,
    vehicle_position,
)
from trustroute.harness.simulation.incidents.oncoming import (
    TRUCK_SPEED,
    OncomingVehicle,
    oncoming_possible,
    schedule_oncoming,
)

KIND = "truck"
PARKED_TYPE_ID = "trustroute_parked_car"
MEET_RANGE = (0.3, 0.7)               # fraction of the watched stretch where they are timed to meet
P_PARKED = 0.3                        # a parked car on a 300 m town road is common (docs/scenes.md)
PARKED_BEFORE_MEETING = (0.0, 80.0)   # metres before the meeting point, along the truck's way
# Shorter than this, the truck's lane has no room to pass a parked car before it meets the ego:
# the scene is the plain oncoming truck. On Town01 the truck and the ego still stopped head-on for
# good on the 128 m K-L with a 100 m minimum, and with a 40 m minimum they collided or stopped for
# good on the 66 m C-D when the ego turned in from J-C, out of the truck's sight; of Town01's truck
# roads only H-L/L-H (444 m along the outer street) pass 200 m.
PARKED_MIN_LANE = 200.0


PARKED_TYPE = VehicleType(PARKED_TYPE_ID, color=(160, 160, 160, 255), length=4.5)


def define_type(sumo) -> None:
    define_vehicle_type(sumo, PARKED_TYPE)


@dataclass
class TruckIncident:
    road: str
    oncoming: OncomingVehicle
    parked_id: str | None = None
    kind: str = KIND
    sumo_ids: tuple[str, ...] = field(init=False)

    def __post_init__(self) -> None:
        self.sumo_ids = (self.oncoming.vehicle_id,) + ((self.parked_id,) if self.parked_id else ())

    @property
    def vehicle_id(self) -> str:
        return self.oncoming.vehicle_id

    def position(self, sumo) -> tuple[float, float] | None:
        return vehicle_position(sumo, self.oncoming.vehicle_id) if self.oncoming.inserted else None

    def step(self, sumo, ego: EgoState) -> None:
        self.oncoming.step(sumo, ego)

    def measure(self, sumo, ego: EgoState, monitor) -> None:
        self.oncoming.measure(sumo, ego, monitor)

    def is_passed(self, sumo, ego: EgoState) -> bool:
        return not math.isnan(self.oncoming.met_time)   # they have met

    def done(self) -> bool:
        return self.oncoming.done()   # the parked car does nothing per step

    def remove(self, sumo) -> None:
        self.oncoming.remove(sumo)
        if self.parked_id is not None:
            remove_vehicle(sumo, self.parked_id)

    def details(self) -> str:
        return f"{self.oncoming.details()} parked={'yes' if self.parked_id else 'no'}"


def inject(sumo, scene: Scene) -> TruckIncident | None:
    """The truck scene on scene.road; None on a real net whose opposite lane is closed to trucks
    (as where the road has no opposite direction, the scene cannot happen there)."""
    if scene.reverse_road is None:
        raise ValueError(f"truck incident on {scene.road}: the road has no opposite direction")
    if not oncoming_possible(sumo, scene):
        return None
    fraction = float(scene.draw("meet_fraction", lambda rng: rng.uniform(*MEET_RANGE)))
    parked = bool(scene.draw("parked", lambda rng: rng.random() < P_PARKED))
    before = float(scene.draw("parked_before_meeting", lambda rng: rng.uniform(*PARKED_BEFORE_MEETING)))
    # On the stretch watched before the ego's commit point: on Town01's 50-70 m roads a meeting
    # beyond it would come after the truck has left the simulation with the road's observation.
    meet_at = fraction * scene.watched
    eta = (scene.ego_distance + meet_at) / scene.road_speed
    # The truck pulls out round the parked car when it reaches it, `before` metres ahead of the
    # meeting point; the ego is then before * road_speed / TRUCK_SPEED metres short of that point.
    # Unless the ego is already on the road there, SUMO's gap acceptance cannot see it, the truck
    # commits to the ego's lane, and on a short road (Town01's are 50-250 m) the two stop head-on
    # for good. So the parked car stands no further back than keeps the ego on the road.
    before = min(before, meet_at * TRUCK_SPEED / scene.road_speed)
    parked_id = None
    reverse_length = lane_length(sumo, f"{scene.reverse_road}_{scene.reverse_lane}")
    if parked and scene.overtake and reverse_length >= PARKED_MIN_LANE:
        parked_id = f"{scene.prefix}.parked"
        on_reverse = reverse_length - meet_at - before
        park_vehicle(sumo, parked_id, f"{parked_id}_route", scene.reverse_road, max(on_reverse, 5.0),
                     PARKED_TYPE_ID, lane=scene.reverse_lane)
    oncoming = schedule_oncoming(sumo, scene, meet_at=meet_at, meet_in=eta,
                                 vehicle_id=f"{scene.prefix}.truck")
    return TruckIncident(road=scene.road, oncoming=oncoming, parked_id=parked_id)
