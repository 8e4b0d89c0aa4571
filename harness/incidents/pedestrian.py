"""Pedestrian incident: a person crossing the road at its start, on the prioritised crossing.

For a road V-W the net has a crossing at V over V-W and W-V (networks/sumo_net.py). The person
starts on the sidewalk of W-V just before V and walks over that crossing to the sidewalk of V-W,
so as the ego turns into V-W the person is on the crossing ahead and the ego must yield.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

from trustroute.harness.incidents.base import EgoState, Scene

KIND = "pedestrian"
START_BEFORE_JUNCTION = 3.0   # metres before the end of the opposite sidewalk
ARRIVAL_POSITION = 6.0        # metres along the incident road's sidewalk
WALKING_SPEED = 1.2           # m/s: slow enough to be on the crossing when the ego arrives
PASSED_AFTER = 25.0           # metres into the road: the crossing is behind the ego


@dataclass
class PedestrianIncident:
    road: str
    person_id: str
    kind: str = KIND
    sumo_ids: tuple[str, ...] = field(init=False)

    def __post_init__(self) -> None:
        self.sumo_ids = (self.person_id,)

    def _alive(self, sumo) -> bool:
        return self.person_id in sumo.person.getIDList()

    def position(self, sumo) -> tuple[float, float] | None:
        return tuple(sumo.person.getPosition(self.person_id)) if self._alive(sumo) else None

    def step(self, sumo, ego: EgoState) -> None:
        return None

    def is_passed(self, sumo, ego: EgoState) -> bool:
        return ego.road == self.road and ego.lane_position > PASSED_AFTER

    def remove(self, sumo) -> None:
        # Also reaches an object still waiting for insertion; one already gone raises, and that is fine.
        with contextlib.suppress(sumo.TraCIException):
            sumo.person.remove(self.person_id)


def inject(sumo, scene: Scene) -> PedestrianIncident:
    if scene.reverse_road is None:
        raise ValueError(f"pedestrian incident on {scene.road}: the road has no opposite direction")
    person_id = f"{scene.prefix}.pedestrian"
    start = max(0.0, sumo.lane.getLength(f"{scene.reverse_road}_0") - START_BEFORE_JUNCTION)
    sumo.person.add(person_id, scene.reverse_road, start, depart=-3, typeID="DEFAULT_PEDTYPE")
    sumo.person.setSpeed(person_id, WALKING_SPEED)
    sumo.person.appendWalkingStage(person_id, [scene.reverse_road, scene.road], ARRIVAL_POSITION)
    sumo.person.setColor(person_id, (255, 140, 0, 255))
    return PedestrianIncident(road=scene.road, person_id=person_id)
