"""Truck incident: a slow heavy vehicle ahead of the ego on its road (one lane: no overtaking).

The truck is inserted a short way into the road when the ego commits to it, drives at
`TRUCK_SPEED` and leaves the simulation at the end of the road; the ego catches up and follows.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from trustroute.harness.incidents.base import (
    EgoState,
    Scene,
    remove_vehicle,
    vehicle_position,
    vehicle_present,
)

KIND = "truck"
TYPE_ID = "trustroute_truck"
TRUCK_SPEED = 6.0       # m/s, against 13.89 on the road
START_POSITION = 30.0   # metres into the road


def define_type(sumo) -> None:
    sumo.vehicletype.copy("DEFAULT_VEHTYPE", TYPE_ID)
    sumo.vehicletype.setVehicleClass(TYPE_ID, "truck")
    sumo.vehicletype.setShapeClass(TYPE_ID, "truck")
    sumo.vehicletype.setLength(TYPE_ID, 12.0)
    sumo.vehicletype.setMaxSpeed(TYPE_ID, TRUCK_SPEED)
    sumo.vehicletype.setAccel(TYPE_ID, 1.0)
    sumo.vehicletype.setImperfection(TYPE_ID, 0.0)
    sumo.vehicletype.setColor(TYPE_ID, (120, 120, 255, 255))


@dataclass
class TruckIncident:
    road: str
    vehicle_id: str
    kind: str = KIND
    sumo_ids: tuple[str, ...] = field(init=False)

    def __post_init__(self) -> None:
        self.sumo_ids = (self.vehicle_id,)

    def position(self, sumo) -> tuple[float, float] | None:
        return vehicle_position(sumo, self.vehicle_id)

    def step(self, sumo, ego: EgoState) -> None:
        return None

    def is_passed(self, sumo, ego: EgoState) -> bool:
        # Passed once the truck has left the ego's road (it drives off at the road's end).
        return ego.road == self.road and not vehicle_present(sumo, self.vehicle_id)

    def remove(self, sumo) -> None:
        remove_vehicle(sumo, self.vehicle_id)


def inject(sumo, scene: Scene) -> TruckIncident:
    vehicle_id = f"{scene.prefix}.truck"
    route_id = f"{scene.prefix}.truck_route"
    position = min(START_POSITION, 0.25 * scene.road_length)
    sumo.route.add(route_id, [scene.road])
    sumo.vehicle.add(vehicle_id, route_id, typeID=TYPE_ID, depart="now", departLane="best",
                     departPos=f"{position:.2f}", departSpeed="max")
    sumo.vehicle.setLaneChangeMode(vehicle_id, 0)
    return TruckIncident(road=scene.road, vehicle_id=vehicle_id)
