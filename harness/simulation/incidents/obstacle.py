"""Obstacle incident (construction): a broken-down vehicle parked in the ego's lane for good.

The obstacle (a broken-down car, or with probability `P_BICYCLE` a broken bicycle) stands at a
drawn fraction of the road (`POSITION_RANGE`) with a stop that never ends: it does not leave by
itself. The ego passes it with SUMO's own opposite-direction overtaking (the net declares the
two directions neighbours, networks/sumo_net.py): it pulls into the oncoming lane when the gap
allows and waits behind the obstacle otherwise. With probability `P_ONCOMING` an oncoming
vehicle (a truck) is timed to pass the obstacle `ONCOMING_OFFSET` seconds (drawn) after the ego
would reach it at free speed, so the overtake has to wait for it; with probability `P_UNSEEN`
it turns in unseen at the road's far end (`oncoming.schedule_oncoming`), the scene's rare
hazard: a truck that appears while the ego may already be in the oncoming lane.
On a real net without an opposite lane to overtake through and with a single lane (Scene.overtake,
Scene.lanes) the obstacle stands for `BLOCKED_SECONDS` after the ego's free-speed arrival and then
drives off: the ego waits behind it instead of overtaking. Draws: docs/scenes.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from trustroute.harness.simulation.incidents.base import (
    EgoState,
    Scene,
    VehicleType,
    define_vehicle_type,
    park_vehicle,
    remove_vehicle,
    vehicle_position,
)
from trustroute.harness.simulation.incidents.oncoming import (
    OncomingVehicle,
    oncoming_possible,
    schedule_oncoming,
)

KIND = "obstacle"
TYPE_ID = "trustroute_obstacle"
BICYCLE_TYPE_ID = "trustroute_broken_bicycle"
POSITION_RANGE = (0.35, 0.55)   # fraction of the road where the obstacle stands (uniform)
P_BICYCLE = 0.3
P_ONCOMING = 0.5
ONCOMING_OFFSET = (-4.0, 6.0)   # s, uniform: when the oncoming vehicle passes the obstacle,
                                # relative to the ego's free-speed arrival there
P_UNSEEN = 0.2                  # the oncoming vehicle turns in unseen at the road's far end
BLOCKED_SECONDS = 20.0          # s: how long an obstacle nobody can pass blocks after the ego arrives


OBSTACLE_TYPES = (
    VehicleType(TYPE_ID, color=(255, 200, 0, 255), vehicle_class="passenger", length=4.5),
    # the passenger class: a broken bicycle may stand in a car lane
    VehicleType(BICYCLE_TYPE_ID, color=(255, 200, 0, 255), vehicle_class="passenger",
                shape_class="bicycle", length=1.8, width=0.65),
)


def define_type(sumo) -> None:
    for vehicle_type in OBSTACLE_TYPES:
        define_vehicle_type(sumo, vehicle_type)


@dataclass
class ObstacleIncident:
    road: str
    vehicle_id: str
    position_on_road: float
    bicycle: bool
    oncoming: OncomingVehicle | None = None
    unseen: bool = False           # the oncoming vehicle turns in at the road's far end, unseen
    kind: str = KIND
    sumo_ids: tuple[str, ...] = field(init=False)

    def __post_init__(self) -> None:
        self.sumo_ids = (self.vehicle_id,) + ((self.oncoming.vehicle_id,) if self.oncoming else ())

    def position(self, sumo) -> tuple[float, float] | None:
        return vehicle_position(sumo, self.vehicle_id)

    def step(self, sumo, ego: EgoState) -> None:
        if self.oncoming is not None:
            self.oncoming.step(sumo, ego)

    def measure(self, sumo, ego: EgoState, monitor) -> None:
        if self.oncoming is not None:
            self.oncoming.measure(sumo, ego, monitor)

    def done(self) -> bool:
        # The parked object does nothing per step; an oncoming vehicle acts until it has left.
        return self.oncoming is None or self.oncoming.done()

    def is_passed(self, sumo, ego: EgoState) -> bool:
        # Past it on its own road, or on the oncoming lane beside and beyond it.
        if ego.road == self.road:
            return ego.lane_position > self.position_on_road
        return False

    def remove(self, sumo) -> None:
        remove_vehicle(sumo, self.vehicle_id)
        if self.oncoming is not None:
            self.oncoming.remove(sumo)

    def details(self) -> str:
        text = f"object={'bicycle' if self.bicycle else 'car'} position={self.position_on_road:.1f}"
        if self.oncoming is None:
            return text + " oncoming=none"
        return text + f" {self.oncoming.details()} unseen={'yes' if self.unseen else 'no'}"


def inject(sumo, scene: Scene) -> ObstacleIncident:
    vehicle_id = f"{scene.prefix}.obstacle"
    fraction = scene.draw("position_fraction", lambda rng: rng.uniform(*POSITION_RANGE))
    bicycle = bool(scene.draw("bicycle", lambda rng: rng.random() < P_BICYCLE))
    with_oncoming = bool(scene.draw("oncoming", lambda rng: rng.random() < P_ONCOMING))
    offset = float(scene.draw("oncoming_offset", lambda rng: rng.uniform(*ONCOMING_OFFSET)))
    unseen = bool(scene.draw("unseen", lambda rng: rng.random() < P_UNSEEN))
    position = fraction * scene.road_length
    passable = scene.overtake or scene.lanes > 1
    duration = 1e9 if passable else (scene.ego_distance + position) / scene.road_speed + BLOCKED_SECONDS
    park_vehicle(sumo, vehicle_id, f"{scene.prefix}.obstacle_route", scene.road, position,
                 BICYCLE_TYPE_ID if bicycle else TYPE_ID, lane=scene.lane, duration=duration)
    oncoming = None
    if with_oncoming and oncoming_possible(sumo, scene):
        eta = (scene.ego_distance + position) / scene.road_speed
        oncoming = schedule_oncoming(sumo, scene, meet_at=position, meet_in=eta + offset,
                                     vehicle_id=f"{scene.prefix}.oncoming", from_upstream=not unseen)
    return ObstacleIncident(road=scene.road, vehicle_id=vehicle_id, position_on_road=position,
                            bicycle=bicycle, oncoming=oncoming, unseen=unseen and oncoming is not None)
