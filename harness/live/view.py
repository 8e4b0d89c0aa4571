"""What the participant station draws: the net's lanes once, and per frame what is around the ego.

`net_view` reads the town's SUMO net (sumolib) into lane shapes in SUMO's coordinates, internal
(junction) lanes and pedestrian crossings included, served once per connection (/api/net).
`surroundings` reads, at frame time only, every other vehicle and person within VIEW_RADIUS of
the ego from the running simulation: background traffic, and the incidents' SUMO objects (ids
"inc<road index>.<role>": the obstacle, the oncoming vehicle, the parked truck, the pedestrian).
Reading changes nothing in the simulation. Each object carries what the driver's view draws, in
the items the frame's schema names and describes (harness/live/protocol.py `Frame`, `SEEN_VEHICLE`
and `SEEN_PERSON`); its handle is stable within the episode, so the station interpolates one
object between frames, and the sizes are read once per object (`Statics`). A SUMO step is 0.5 s
of simulated time, so at wall-clock pace the steps alone give two frames a second;
`dead_reckoned` fills the time between them (each vehicle moved on at its speed and heading),
marked as predicted.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

from trustroute.networks.road import Road

VIEW_RADIUS = 150.0   # metres around the ego that a frame describes
INCIDENT_PREFIX = "inc"
# the signals a frame carries, SUMO's four lowest bits (their meanings: protocol.py `Frame.vehicles`)
SIGNAL_BITS = 0b1111
ROUTE_AHEAD = 6       # roads of the ego's route a frame names, from the one it is on


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
                          "internal": edge.getFunction() != "", "kind": lane_kind(edge, lane),
                          "index": lane.getIndex(),
                          "shape": [[round(x, 2), round(y, 2)] for x, y in lane.getShape()]})
    nodes = [node for node in net.getNodes() if node.getType() != "internal"]
    junctions = {node.getID(): [round(c, 2) for c in node.getCoord()] for node in nodes}
    areas = [[[round(x, 2), round(y, 2)] for x, y, *_ in node.getShape()] for node in nodes
             if len(node.getShape()) >= 3]
    (x0, y0), (x1, y1) = net.getBBoxXY()
    return {"lanes": lanes, "junctions": junctions, "areas": areas, "bounds": [x0, y0, x1, y1]}


def lane_kind(edge, lane) -> str:
    """What a lane is to the driver's view: "crossing", "walkingarea", "sidewalk" (pedestrians
    only), "internal" (a road lane inside a junction) or "road"."""
    function = edge.getFunction()
    if function in ("crossing", "walkingarea"):
        return function
    if lane.allows("pedestrian") and not lane.allows("passenger"):
        return "sidewalk"
    return "internal" if function else "road"


def next_junction(road: str) -> str | None:
    """The junction at the end of a town road ("A-B" -> "B"); None inside a junction."""
    parsed = Road.parse_or_none(road)
    return None if parsed is None else parsed.to_junction


def role(sumo_id: str) -> str:
    """What an object is to the participant: an incident object's role, or "traffic"."""
    if sumo_id.startswith(INCIDENT_PREFIX) and "." in sumo_id:
        return sumo_id.split(".", 1)[1]
    return "traffic"


class Statics:
    """What does not change about an object while it is in the simulation, read once: its handle
    (a number given in the order objects are first seen, so no SUMO id reaches the page) and, for
    a vehicle, [length, width, height, shape class]."""

    def __init__(self) -> None:
        self.handles: dict[str, int] = {}
        self.sizes: dict[str, list] = {}

    def handle(self, sumo_id: str) -> int:
        return self.handles.setdefault(sumo_id, len(self.handles))

    def vehicle(self, sumo, vehicle: str) -> list:
        if vehicle not in self.sizes:
            vehicle_type = sumo.vehicle.getTypeID(vehicle)
            self.sizes[vehicle] = [round(sumo.vehicletype.getLength(vehicle_type), 2),
                                   round(sumo.vehicletype.getWidth(vehicle_type), 2),
                                   round(sumo.vehicletype.getHeight(vehicle_type), 2),
                                   sumo.vehicletype.getShapeClass(vehicle_type)]
        return self.sizes[vehicle]


def surroundings(sumo, ego_id: str, x: float, y: float, statics: Statics | None = None) -> dict:
    """{"vehicles": [...], "persons": [...]}: every other vehicle and every person within
    VIEW_RADIUS of (x, y), as a frame's `vehicles` and `persons` (harness/live/protocol.py `Frame`
    describes their items)."""
    statics = statics if statics is not None else Statics()
    vehicles, persons = [], []
    for vehicle in sumo.vehicle.getIDList():
        if vehicle == ego_id:
            continue
        vx, vy = sumo.vehicle.getPosition(vehicle)
        if math.hypot(vx - x, vy - y) <= VIEW_RADIUS:
            angle = round(sumo.vehicle.getAngle(vehicle), 1)
            speed = round(sumo.vehicle.getSpeed(vehicle), 2)
            vehicles.append([round(vx, 2), round(vy, 2), angle, role(vehicle), speed, statics.handle(vehicle),
                             *statics.vehicle(sumo, vehicle), sumo.vehicle.getSignals(vehicle) & SIGNAL_BITS])
    for person in sumo.person.getIDList():
        px, py = sumo.person.getPosition(person)
        if math.hypot(px - x, py - y) <= VIEW_RADIUS:
            persons.append([round(px, 2), round(py, 2), role(person), statics.handle(person),
                            round(sumo.person.getAngle(person), 1)])
    return {"vehicles": vehicles, "persons": persons}


def ego_view(sumo, ego_id: str, statics: Statics) -> dict:
    """The ego's own part of a frame: its size, signals and the roads of its route from the one it
    is on (the next turn, and the route on the mini-map)."""
    length, width, _, _ = statics.vehicle(sumo, ego_id)
    route = sumo.vehicle.getRoute(ego_id)
    index = max(sumo.vehicle.getRouteIndex(ego_id), 0)
    return {"length": length, "width": width, "signals": sumo.vehicle.getSignals(ego_id) & SIGNAL_BITS,
            "route": list(route[index:index + ROUTE_AHEAD])}


def moved_on(x: float, y: float, angle: float, speed: float, seconds: float) -> tuple[float, float]:
    """(x, y) after `seconds` at `speed` along SUMO's `angle` (degrees clockwise from north)."""
    heading = math.radians(angle)
    return x + speed * seconds * math.sin(heading), y + speed * seconds * math.cos(heading)


def dead_reckoned(frame: dict, seconds: float) -> dict:
    """A frame between two SUMO steps: the stepped `frame` moved on `seconds` of simulated time,
    the ego and every vehicle along its heading at its speed (persons, at walking pace, stay).
    It is marked `predicted`: only the stepped frames are the simulation's state."""
    x, y = moved_on(frame["x"], frame["y"], frame["angle"], frame["speed"], seconds)
    vehicles = [[*moved_on(vx, vy, angle, speed, seconds), angle, kind, speed, *rest]
                for vx, vy, angle, kind, speed, *rest in frame["vehicles"]]
    return {**frame, "t": frame["t"] + seconds, "x": round(x, 2), "y": round(y, 2),
            "vehicles": [[round(v[0], 2), round(v[1], 2), *v[2:]] for v in vehicles], "predicted": True}
