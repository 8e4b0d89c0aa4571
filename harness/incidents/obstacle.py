"""Obstacle incident (construction): a stopped vehicle closing the ego's lane mid-road.

The road has one vehicle lane, so the ego must stop and wait behind it; once the ego has waited
`CLEAR_AFTER` seconds close behind, the lane is cleared (the vehicle is removed) and the ego drives
on. The obstacle stands at `POSITION_FRACTION` of the road.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from trustroute.harness.incidents.base import EgoState, Scene, remove_vehicle, vehicle_position

KIND = "obstacle"
TYPE_ID = "trustroute_obstacle"
POSITION_FRACTION = 0.4
CLEAR_AFTER = 4.0             # seconds the ego waits, stopped behind the obstacle
WAITING_GAP = 30.0            # metres: "close behind"
STOPPED_SPEED = 0.1


def define_type(sumo) -> None:
    sumo.vehicletype.copy("DEFAULT_VEHTYPE", TYPE_ID)
    sumo.vehicletype.setVehicleClass(TYPE_ID, "passenger")
    sumo.vehicletype.setLength(TYPE_ID, 6.0)
    sumo.vehicletype.setColor(TYPE_ID, (255, 200, 0, 255))
    sumo.vehicletype.setShapeClass(TYPE_ID, "truck")


@dataclass
class ObstacleIncident:
    road: str
    vehicle_id: str
    position_on_road: float
    kind: str = KIND
    sumo_ids: tuple[str, ...] = field(init=False)
    waited: float = 0.0
    cleared_at: float | None = None
    _last_time: float | None = None

    def __post_init__(self) -> None:
        self.sumo_ids = (self.vehicle_id,)

    def position(self, sumo) -> tuple[float, float] | None:
        return vehicle_position(sumo, self.vehicle_id)

    def step(self, sumo, ego: EgoState) -> None:
        dt = 0.0 if self._last_time is None else ego.time - self._last_time
        self._last_time = ego.time
        if self.cleared_at is not None or ego.road != self.road:
            return
        behind = 0.0 < self.position_on_road - ego.lane_position < WAITING_GAP
        if behind and ego.speed < STOPPED_SPEED:
            self.waited += dt
            if self.waited >= CLEAR_AFTER:
                self.remove(sumo)
                self.cleared_at = ego.time

    def is_passed(self, sumo, ego: EgoState) -> bool:
        return ego.road == self.road and ego.lane_position > self.position_on_road

    def remove(self, sumo) -> None:
        remove_vehicle(sumo, self.vehicle_id)


def inject(sumo, scene: Scene) -> ObstacleIncident:
    vehicle_id = f"{scene.prefix}.obstacle"
    route_id = f"{scene.prefix}.obstacle_route"
    position = POSITION_FRACTION * scene.road_length
    sumo.route.add(route_id, [scene.road])
    sumo.vehicle.add(vehicle_id, route_id, typeID=TYPE_ID, depart="now", departLane="best",
                     departPos=f"{position:.2f}", departSpeed="0")
    sumo.vehicle.setSpeedMode(vehicle_id, 0)
    sumo.vehicle.setSpeed(vehicle_id, 0.0)
    sumo.vehicle.setLaneChangeMode(vehicle_id, 0)
    return ObstacleIncident(road=scene.road, vehicle_id=vehicle_id, position_on_road=position)
