"""What the participant station draws: the net's lanes once, and per frame what is around the ego.

`net_view` reads the town's SUMO net (sumolib) into lane shapes in SUMO's coordinates, internal
(junction) lanes and pedestrian crossings included, served once per connection (/api/net).
`surroundings` reads, at frame time only, every other vehicle and person within VIEW_RADIUS of
the ego from the running simulation: background traffic, and the incidents' SUMO objects (ids
"inc<road index>.<role>": the obstacle, the oncoming vehicle, the parked truck, the pedestrian).
Reading changes nothing in the simulation. A SUMO step is 0.5 s of simulated time, so at wall-clock
pace the steps alone give two frames a second; `dead_reckoned` fills the time between them (each
vehicle moved on at its speed and heading), marked as predicted.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

from trustroute.networks.road import Road

VIEW_RADIUS = 150.0   # metres around the ego that a frame describes
INCIDENT_PREFIX = "inc"


@lru_cache(maxsize=4)
def net_view(net_path: str) -> dict:
    """{"lanes": [{"id", "width", "internal", "shape": [[x, y], ...]}], "junctions": {id: [x, y]},
    "bounds": [x0, y0, x1, y1]} (junctions: the town's, the ends of its roads)."""
    import sumolib

    net = sumolib.net.readNet(str(Path(net_path)), withInternal=True, withPedestrianConnections=True)
    lanes = []
    for edge in net.getEdges(withInternal=True):
        for lane in edge.getLanes():
            lanes.append({"id": lane.getID(), "width": round(lane.getWidth(), 2),
                          "internal": edge.getFunction() != "",
                          "shape": [[round(x, 2), round(y, 2)] for x, y in lane.getShape()]})
    junctions = {node.getID(): [round(c, 2) for c in node.getCoord()] for node in net.getNodes()
                 if node.getType() != "internal"}
    (x0, y0), (x1, y1) = net.getBBoxXY()
    return {"lanes": lanes, "junctions": junctions, "bounds": [x0, y0, x1, y1]}


def next_junction(road: str) -> str | None:
    """The junction at the end of a town road ("A-B" -> "B"); None inside a junction."""
    parsed = Road.parse_or_none(road)
    return None if parsed is None else parsed.to_junction


def role(sumo_id: str) -> str:
    """What an object is to the participant: an incident object's role, or "traffic"."""
    if sumo_id.startswith(INCIDENT_PREFIX) and "." in sumo_id:
        return sumo_id.split(".", 1)[1]
    return "traffic"


def surroundings(sumo, ego_id: str, x: float, y: float) -> dict:
    """{"vehicles": [[x, y, angle, kind, speed]], "persons": [[x, y, kind]]} within VIEW_RADIUS of
    (x, y); kind is an incident object's role ("obstacle", "oncoming", "parked", "pedestrian"),
    else "traffic"."""
    vehicles, persons = [], []
    for vehicle in sumo.vehicle.getIDList():
        if vehicle == ego_id:
            continue
        vx, vy = sumo.vehicle.getPosition(vehicle)
        if math.hypot(vx - x, vy - y) <= VIEW_RADIUS:
            angle = round(sumo.vehicle.getAngle(vehicle), 1)
            speed = round(sumo.vehicle.getSpeed(vehicle), 2)
            vehicles.append([round(vx, 2), round(vy, 2), angle, role(vehicle), speed])
    for person in sumo.person.getIDList():
        px, py = sumo.person.getPosition(person)
        if math.hypot(px - x, py - y) <= VIEW_RADIUS:
            persons.append([round(px, 2), round(py, 2), role(person)])
    return {"vehicles": vehicles, "persons": persons}


def moved_on(x: float, y: float, angle: float, speed: float, seconds: float) -> tuple[float, float]:
    """(x, y) after `seconds` at `speed` along SUMO's `angle` (degrees clockwise from north)."""
    heading = math.radians(angle)
    return x + speed * seconds * math.sin(heading), y + speed * seconds * math.cos(heading)


def dead_reckoned(frame: dict, seconds: float) -> dict:
    """A frame between two SUMO steps: the stepped `frame` moved on `seconds` of simulated time,
    the ego and every vehicle along its heading at its speed (persons, at walking pace, stay).
    It is marked `predicted`: only the stepped frames are the simulation's state."""
    x, y = moved_on(frame["x"], frame["y"], frame["angle"], frame["speed"], seconds)
    vehicles = [[*moved_on(vx, vy, angle, speed, seconds), angle, kind, speed]
                for vx, vy, angle, kind, speed in frame["vehicles"]]
    return {**frame, "t": frame["t"] + seconds, "x": round(x, 2), "y": round(y, 2),
            "vehicles": [[round(v[0], 2), round(v[1], 2), *v[2:]] for v in vehicles], "predicted": True}
