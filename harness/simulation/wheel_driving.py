"""Continuous manual driving: a person's steering wheel and pedals drive a vehicle model whose
pose is the ego's in SUMO.

- the vehicle model (vehicle_model.py `integrate`): a kinematic bicycle model of the person's car.
- `ManualDriving.step(sumo, controls, seconds)`: one SUMO step of the person's driving: the model
  integrated over the step, the ego placed at the model's pose for the next simulation step with
  `vehicle.moveToXY(..., keepRoute=KEEP_ROUTE_FREE)` where that pose is on its road or the
  oncoming one (it may leave its lane and cross into the oncoming lane), and with
  keepRoute=KEEP_ROUTE elsewhere (off the road, in a junction: SUMO keeps the ego at the nearest
  place on its route, which the episode needs); what the previous step's placement led to is
  reported as events.
- SUMO's free placement replaces the ego's route by the edge it was mapped to (the oncoming road,
  say); once the ego is back on an edge of its planned route, `ManualDriving` gives SUMO the
  planned route again from there (`restore_route`), so the episode's routing goes on.

Events (dicts with `t`, `type` and details), each logged when it begins:
- `off_road`: the ego's centre is on no lane open to cars (SUMO maps it to none, or to a lane
  farther away than half its width); `on_road` when it is back;
- `oncoming`: on a lane of the opposite direction of its road or of another road of its route;
  `own_lane` when back on its route;
- `collision` (`object`, `speed`): the ego's footprint overlaps a vehicle's or a person's (oriented
  rectangles, `overlaps`). What a collision does: the ego stops where it is (the model's speed is
  set to 0) and stands there while it touches what it hit, whatever the pedals say; the person
  keeps control and may hand back wherever the ego is (the lane rule below is waived after a
  collision): the autopilot then takes it from the nearest place on its route (`release`). The
  episode goes on, as it does after SUMO's own collisions in simulated studies
  (`--collision.action warn`).
- `stopped_off_road` (`distance`): the model's front is farther than OFF_ROUTE_LIMIT from where
  SUMO keeps the ego on its route (off the road, or on a road it is not routed on, which counts as
  `off_road` too): the car stops there and stands whatever the pedals say; the person may hand
  back from there, and the autopilot takes it from the nearest place on its route (`release`), as
  after a collision. So no placement ever asks SUMO to map the ego farther from its route than it
  can (100 m), and the episode goes on whatever the person does with the wheel.

`Wheel` is the hook a live episode calls every SUMO step (harness/live/worker.py), with the hold
before the junction (the assisted driving's rule, manual_driving.py `hold_distance`).
`ManualDriving.may_hand_back` is the paper's hand-back rule for a person driving this way: the
autopilot takes over again only with the ego on a lane of its planned route (by the model's pose).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import NamedTuple

from trustroute.harness.simulation.driving_style import MANUAL
from trustroute.harness.simulation.manual_driving import (
    HOLD_MARGIN,
    RoadChain,
    hold_distance,
    one_edge,
    to_road_end,
)
from trustroute.harness.simulation.manual_measures import TTC_RANGE, Sample, signed_offset, ttc_ahead
from trustroute.harness.simulation.vehicle_model import (
    DEFAULT_PARAMS,
    Controls,
    Pose,
    VehicleParams,
    corners,
    forward,
    integrate,
    overlaps,
)

KEEP_ROUTE = 1               # moveToXY: the nearest place on the ego's route
KEEP_ROUTE_FREE = 2          # moveToXY: any lane, and off the net too
MOVE_TELEPORT = 1            # moveTo's reason: off the net and back on it (SUMO's lane state reset)
PERSON_RADIUS = 0.3          # m: a person's footprint is a square of this half side
CREEP_SPEED = 3.0            # m/s: held off its lane, the car is not driven faster than this
CREEP_BRAKE = 0.5            # the brake applied above CREEP_SPEED then (of full braking)
NEAR = 25.0                  # m: objects farther than this from the ego are not tested for contact
# SUMO's speed mode while the model drives: none of its checks. With the autopilot's (31) SUMO
# would bring its speed to the model's within its own acceleration and deceleration limits only,
# so a car standing against what it hit would be logged still rolling at up to its speed before.
MODEL_SPEED_MODE = 0
# m: the model's front farther than this from where SUMO keeps the ego on its route: the car has
# left its road and stops there (SUMO cannot map a placement beyond 100 m of its route at all)
OFF_ROUTE_LIMIT = 10.0


def nearest_on(shape, x: float, y: float) -> tuple[float, float, float]:
    """The point of a polyline nearest (x, y), and the polyline's angle there (SUMO's degrees)."""
    best = (math.inf, 0.0, 0.0, 0.0)
    for (x0, y0), (x1, y1) in zip(shape, shape[1:], strict=False):
        dx, dy = x1 - x0, y1 - y0
        length2 = dx * dx + dy * dy
        along = 0.0 if length2 == 0.0 else min(max(((x - x0) * dx + (y - y0) * dy) / length2, 0.0), 1.0)
        px, py = x0 + along * dx, y0 + along * dy
        distance = math.hypot(x - px, y - py)
        if distance < best[0]:
            best = (distance, px, py, math.degrees(math.atan2(dx, dy)) % 360.0)
    return best[1], best[2], best[3]


def off_road(sumo, x: float, y: float) -> bool:
    """Whether (x, y) is on no lane open to cars: farther from the nearest one's centre line than
    half its width."""
    try:
        edge, position, index = sumo.simulation.convertRoad(x, y, False, "passenger")
    except Exception:   # no lane open to cars near enough to be matched at all
        return True
    if not edge:
        return True
    lane = f"{edge}_{index}"
    cx, cy = sumo.simulation.convert2D(edge, position, index)
    return math.hypot(x - cx, y - cy) > sumo.lane.getWidth(lane) / 2


def nearest_car_lane(sumo, edge: str, x: float, y: float) -> int:
    """The index of the lane of `edge` open to cars whose centre line is nearest (x, y)."""
    best = (math.inf, 0)
    for index in range(sumo.edge.getLaneNumber(edge)):
        lane = f"{edge}_{index}"
        allowed = sumo.lane.getAllowed(lane)
        if allowed and "passenger" not in allowed:
            continue
        px, py, _ = nearest_on(sumo.lane.getShape(lane), x, y)
        best = min(best, (math.hypot(x - px, y - py), index))
    return best[1]


def restore_route(sumo, vehicle_id: str, route: list[str]) -> bool:
    """After a free placement: the planned route again from the edge the ego is on, when that
    edge is on it (True then). A route SUMO has that goes on from there as planned is kept: the
    episode may have extended it meanwhile (a road's choice is made while the person drives)."""
    edge = sumo.vehicle.getRoadID(vehicle_id)
    if edge not in route:
        return False
    wanted = route[route.index(edge):]
    current = list(sumo.vehicle.getRoute(vehicle_id))
    ahead = current[current.index(edge):] if edge in current else []
    if ahead[:len(wanted)] != wanted:
        sumo.vehicle.setRoute(vehicle_id, wanted)
    return True


@dataclass
class ManualDriving:
    """A person driving the ego by wheel and pedals, one SUMO step at a time."""

    vehicle_id: str
    pose: Pose
    route: list[str]                  # the planned route: the road and the next when chosen
    length: float = 4.5
    width: float = 1.8
    params: VehicleParams = DEFAULT_PARAMS
    events: list[dict] = field(default_factory=list)
    where: str = "own_lane"           # own_lane, oncoming or off_road
    touching: set[str] = field(default_factory=set)
    collided: bool = False
    current: Pose | None = None       # the pose at SUMO's time now (the model runs a step ahead)
    lane_index: int = 0               # the lane of its road the ego was in at the takeover
    edge: str = ""                    # the edge of its route it was on last (its own road)
    stranded: bool = False            # stopped off its route (`stopped_off_road`) until the hand-back
    junctions: dict[str, tuple[str, str]] = field(default_factory=dict)   # edge -> (from, to) junction
    # taken over while SUMO's own overtaking had the ego in the oncoming lane: SUMO keeps that state
    # through every placement and, handed back, would drive the ego backwards along its own lane
    # until what it passed stops it; `leave_sumo_opposite` clears it
    sumo_opposite: bool = False

    @classmethod
    def take_over(cls, sumo, vehicle_id: str, **options) -> ManualDriving:
        """From where SUMO has the ego now: no jump of its pose or speed."""
        x, y = sumo.vehicle.getPosition(vehicle_id)
        pose = Pose(x, y, sumo.vehicle.getAngle(vehicle_id), sumo.vehicle.getSpeed(vehicle_id))
        vehicle_type = sumo.vehicle.getTypeID(vehicle_id)
        sumo.vehicle.setSpeedMode(vehicle_id, MODEL_SPEED_MODE)   # the hand-back's style sets SUMO's again
        driving = cls(vehicle_id, pose, list(sumo.vehicle.getRoute(vehicle_id)),
                      length=sumo.vehicletype.getLength(vehicle_type),
                      width=sumo.vehicletype.getWidth(vehicle_type),
                      lane_index=max(0, sumo.vehicle.getLaneIndex(vehicle_id)),
                      edge=sumo.vehicle.getRoadID(vehicle_id), **options)
        if driving.edge not in driving.route and driving.opposite(sumo, driving.edge):
            # SUMO's overtaking: its own road is the route's edge this one runs against
            against = driving.ends(sumo, driving.edge)[::-1]
            own = next(edge for edge in driving.route
                       if not edge.startswith(":") and driving.ends(sumo, edge) == against)
            driving.edge, driving.lane_index = own, nearest_car_lane(sumo, own, x, y)
            driving.sumo_opposite = True
        return driving

    def step(self, sumo, controls: Controls, seconds: float) -> Pose:
        """Read where the last placement put the ego (events), then integrate the person's controls
        over `seconds` and place the ego there for SUMO's next step. Returns the new pose."""
        now = sumo.simulation.getTime()
        self.observe(sumo, now)
        self.current = self.pose   # where the person drives at SUMO's time now (what they see)
        if not self.touching and not self.stranded:   # it stands (until the hand-back)
            self.pose = integrate(self.pose, controls, seconds, self.params)
        pose = self.pose
        sumo.vehicle.moveToXY(self.vehicle_id, "", -1, pose.x, pose.y, pose.angle, self.placement(sumo))
        sumo.vehicle.setSpeed(self.vehicle_id, self.pose.speed)
        return self.pose

    @property
    def may_hand_back(self) -> bool:
        return self.where == "own_lane" or self.collided or self.stranded

    def release(self, sumo, ahead: str | None = None) -> bool:
        """The hand-back: SUMO drives on from here. Away from a lane of the route (after a
        collision, or held off its lane before the junction) the ego is first put at the nearest
        place of its lane on the planned road, facing along it; True then: the planned route is
        to be given back once SUMO has it there (`restore_route`). So is a car that its last
        placement put on a road off its route (free placement maps the model's pose by itself).
        Taken over in a junction and never on a road of its route since, the ego is put on the
        nearest lane open to cars of `ahead` (the first edge of the episode's open road: the one
        after that junction)."""
        now_on = sumo.vehicle.getRoadID(self.vehicle_id)
        off_route = bool(now_on) and not now_on.startswith(":") and now_on not in self.route
        if self.where == "own_lane" and not self.stranded and not off_route:
            return False
        if self.edge and not self.edge.startswith(":"):
            edge, index = self.edge, self.lane_index
        elif ahead in self.route:
            edge, index = ahead, nearest_car_lane(sumo, ahead, self.pose.x, self.pose.y)
        else:
            return False
        x, y, angle = nearest_on(sumo.lane.getShape(f"{edge}_{index}"), self.pose.x, self.pose.y)
        sumo.vehicle.moveToXY(self.vehicle_id, edge, index, x, y, angle, KEEP_ROUTE_FREE)
        return True

    def leave_sumo_opposite(self, sumo) -> bool:
        """After the hand-back of a car taken over in SUMO's own overtaking (`sumo_opposite`), once
        SUMO has it on an edge of its route: SUMO's oncoming-lane state cleared (True then). Only a
        move to another lane clears it (SUMO takes the car off the net and puts it back there), so
        the car goes to another lane of that edge (or of another edge of its route) and straight
        back, within this step: it stays where it is, at its speed."""
        lane = sumo.vehicle.getLaneID(self.vehicle_id)
        if not lane or lane.startswith(":"):
            return False
        edge = sumo.lane.getEdgeID(lane)
        route = list(sumo.vehicle.getRoute(self.vehicle_id))
        if edge not in route:
            return False
        others = [f"{edge}_{index}" for index in range(sumo.edge.getLaneNumber(edge))]
        others.remove(lane)
        others += [f"{other}_0" for other in route if other != edge and not other.startswith(":")]
        if not others:
            return False
        position = sumo.vehicle.getLanePosition(self.vehicle_id)
        speed = sumo.vehicle.getSpeed(self.vehicle_id)
        via = others[0]
        sumo.vehicle.moveTo(self.vehicle_id, via, min(position, sumo.lane.getLength(via)), MOVE_TELEPORT)
        sumo.vehicle.moveTo(self.vehicle_id, lane, position, MOVE_TELEPORT)
        sumo.vehicle.setPreviousSpeed(self.vehicle_id, speed)
        self.sumo_opposite = False
        return True

    def placement(self, sumo) -> int:
        """Free placement on the ego's road and the oncoming one; anywhere else (off the road, a
        junction, another road) SUMO keeps the ego on its route, so the episode's road and route
        stay sound; the events and the person's view follow the model's pose all the same."""
        # SUMO places the front centre, and puts it on no lane at all (which the episode cannot
        # follow) when that point is off every lane: free placement only with it on one
        front = (self.pose.x, self.pose.y)
        if off_road(sumo, *front):
            return KEEP_ROUTE
        edge = sumo.simulation.convertRoad(*front, False, "passenger")[0]
        return KEEP_ROUTE_FREE if edge in self.route or self.opposite(sumo, edge) else KEEP_ROUTE

    def observe(self, sumo, now: float) -> None:
        lane = sumo.vehicle.getLaneID(self.vehicle_id)
        if lane and not lane.startswith(":"):
            if restore_route(sumo, self.vehicle_id, self.route):
                self.edge = sumo.lane.getEdgeID(lane)
        if not self.stranded:   # standing where it stopped: its place is settled
            self.locate(sumo, lane, now)
            self.leash(sumo, now)
        self.contacts(sumo, now)

    def leash(self, sumo, now: float) -> None:
        """Stop the car once the model's front (placed last step) is farther than OFF_ROUTE_LIMIT
        from where SUMO keeps the ego on its route (free placement puts the ego at the model's
        pose, so only a car off its road or on a road off its route gets that far)."""
        x, y = sumo.vehicle.getPosition(self.vehicle_id)
        distance = math.hypot(self.pose.x - x, self.pose.y - y)
        if distance <= OFF_ROUTE_LIMIT:
            return
        place = {"x": round(self.pose.x, 2), "y": round(self.pose.y, 2)}
        if self.where != "off_road":   # on a road it is not routed on: it has left its road too
            self.events.append({"t": now, "type": "off_road", **place})
            self.where = "off_road"
        self.events.append({"t": now, "type": "stopped_off_road", **place, "distance": round(distance, 1)})
        self.pose = replace(self.pose, speed=0.0)
        self.stranded = True

    def locate(self, sumo, lane: str, now: float) -> None:
        fx, fy = forward(self.pose.angle)
        centre = (self.pose.x - fx * self.length / 2, self.pose.y - fy * self.length / 2)
        if not lane or off_road(sumo, *centre):   # by the model's pose: SUMO keeps the ego on the net
            where = "off_road"
        elif lane.startswith(":") or sumo.lane.getEdgeID(lane) in self.route:
            where = "own_lane"
        else:
            where = "oncoming" if self.opposite(sumo, sumo.lane.getEdgeID(lane)) else "own_lane"
        if where != self.where:
            kind = {"off_road": "off_road", "oncoming": "oncoming"}.get(where)
            if kind is None:
                kind = "on_road" if self.where == "off_road" else "own_lane"
            self.events.append({"t": now, "type": kind, "x": round(self.pose.x, 2),
                                "y": round(self.pose.y, 2)})
            self.where = where

    def opposite(self, sumo, edge: str) -> bool:
        """Whether `edge` runs against its own road or another road of its route (the oncoming
        lane of the road it turns into, say, entered from the junction): it joins the junctions of
        one of their edges the other way round, as the net has them (on a built town "V-U" against
        "U-V"; on an imported town the net's own reverse edge of an edge of the road's chain)."""
        if not edge or edge.startswith(":"):
            return False
        start, end = self.ends(sumo, edge)
        own = [self.edge, *self.route]
        return any(self.ends(sumo, mine) == (end, start) for mine in own if mine and not mine.startswith(":"))

    def ends(self, sumo, edge: str) -> tuple[str, str]:
        """The junctions `edge` runs from and to (read once per edge)."""
        if edge not in self.junctions:
            self.junctions[edge] = (sumo.edge.getFromJunction(edge), sumo.edge.getToJunction(edge))
        return self.junctions[edge]

    def contacts(self, sumo, now: float) -> None:
        ego = corners(self.pose.x, self.pose.y, self.pose.angle, self.length, self.width)
        touching = set()
        for other in sumo.vehicle.getIDList():
            if other == self.vehicle_id:
                continue
            ox, oy = sumo.vehicle.getPosition(other)
            if math.hypot(ox - self.pose.x, oy - self.pose.y) > NEAR:
                continue
            other_type = sumo.vehicle.getTypeID(other)
            shape = corners(ox, oy, sumo.vehicle.getAngle(other), sumo.vehicletype.getLength(other_type),
                            sumo.vehicletype.getWidth(other_type))
            if overlaps(ego, shape):
                touching.add(other)
        for person in sumo.person.getIDList():
            px, py = sumo.person.getPosition(person)
            if math.hypot(px - self.pose.x, py - self.pose.y) <= NEAR and overlaps(
                    ego, corners(px, py + PERSON_RADIUS, 0.0,
                                 2 * PERSON_RADIUS, 2 * PERSON_RADIUS)):
                touching.add(person)
        for other in sorted(touching - self.touching):
            self.events.append({"t": now, "type": "collision", "object": other,
                                "speed": round(self.pose.speed, 2)})
            self.pose = replace(self.pose, speed=0.0)   # a crash stops the car; the person keeps control
            self.collided = True
        self.touching = touching


class HoldPoint(NamedTuple):
    """Where the hold before a junction wants the car to stand."""

    remaining: float   # m from the ego (where SUMO has it) to the end of the road it is to stop before
    short_of: float    # m short of that end: the commit point and HOLD_MARGIN, or HOLD_MARGIN alone
    firm: bool         # no hand-back at a commit point comes first: braked as hard as it takes


class Wheel:
    """The hook of a live episode: the person's latest controls drive the ego while they are in
    control (`step`, every SUMO step); a takeover starts the model from SUMO's pose and speed and a
    hand-back gives the ego back to SUMO where it is, at its speed (no jump either way).

    The hand-back rule before the junction (the assisted driving's, manual_driving.py: the same
    `hold_distance`): a person still in control that close to the open road's end is held. In a
    lane of the route the car brakes to a stop and waits for the hand-back (event `hold`). Elsewhere
    (the oncoming lane, off the road) the station guides them back (event `guide_back`) and the
    car is braked above CREEP_SPEED so they can steer back; should the car still be off its lane
    HOLD_MARGIN before the road's end, it brakes to a stop there (event `held_off_lane`) and the
    hand-back is allowed where it stands: the autopilot takes it from the nearest place on its route
    (`ManualDriving.release`), short of the junction either way. A takeover after the junction
    ahead was chosen (the episode's open road is then the next one) is held at the end of the road
    the ego is on, braked as hard as it takes to stop HOLD_MARGIN short of it, or, in the junction
    already, at the next road's commit point (`to_hold_point`).

    A road's end is the end of the last SUMO edge it runs along (`chain`, given by the episode:
    the road itself on a built town, the net's own edges on an imported one), and the distance to
    it is summed over the road's edges still ahead (manual_driving.py `to_road_end`)."""

    def __init__(self, vehicle_id: str, commit_distance: float = 0.0, chain: RoadChain = one_edge) -> None:
        self.vehicle_id = vehicle_id
        self.commit_distance = commit_distance
        self.chain = chain
        self.open_road: str | None = None    # the episode's open road at the last step
        self.behind: str | None = None       # the open road before it: the ego's own until it leaves it
        self.controls = Controls()
        self.driving: ManualDriving | None = None
        self.events: list[dict] = []     # every takeover's events, in order
        self.holding = False             # held before the junction until the hand-back
        self.held_off_lane = False       # stopped off its lane at the road's end: may hand back there
        self.lengths: dict[str, float] = {}
        self.restore: list[str] | None = None   # the planned route, to give back after a release
        self.released: ManualDriving | None = None   # handed back in SUMO's oncoming-lane state
        self.trace: list[Sample] = []    # every manual step: the measures' raw material
        self.shapes: dict[str, list] = {}

    @property
    def may_hand_back(self) -> bool:
        return self.driving is None or self.driving.may_hand_back or self.held_off_lane

    @property
    def pose(self) -> Pose | None:
        """The person's pose at SUMO's time now while they drive (SUMO's own may differ off the
        road, where SUMO keeps the ego on its route), else None."""
        return None if self.driving is None else self.driving.current

    def step(self, sumo, manual: bool, road: str | None = None) -> list[dict]:
        """One SUMO step (`road`: the episode's open road, None: no hold); the events it brought."""
        if road is not None and road != self.open_road:
            self.behind, self.open_road = self.open_road, road
        if not manual:
            if self.restore is not None and restore_route(sumo, self.vehicle_id, self.restore):
                self.restore = None
            if self.released is not None and self.restore is None and self.released.leave_sumo_opposite(sumo):
                self.released = None
            if self.driving is not None:   # handed back: SUMO drives on from the model's pose and speed
                self.follow_route(sumo)   # the episode may have extended it in this very step
                if self.driving.release(sumo, None if road is None else self.chain(road)[0]):
                    self.restore = list(self.driving.route)
                elif self.driving.sumo_opposite:   # where it is: cleared now
                    self.driving.leave_sumo_opposite(sumo)
                if self.driving.sumo_opposite:   # placed by the release: cleared once SUMO has it there
                    self.released = self.driving
                self.driving = None
                sumo.vehicle.setSpeed(self.vehicle_id, -1)
            self.holding = self.held_off_lane = False
            return []
        if self.driving is None:
            self.driving = ManualDriving.take_over(sumo, self.vehicle_id)
            self.driving.sumo_opposite |= self.released is not None   # taken over again before it was cleared
            self.released = None
            self.controls = Controls()
        self.follow_route(sumo)
        seen = len(self.driving.events)
        # no hold without a road, nor for a car stopped off its road
        controls = self.controls if road is None or self.driving.stranded else self.held_controls(sumo, road)
        self.driving.step(sumo, controls, sumo.simulation.getDeltaT())
        self.sample(sumo)
        new = self.driving.events[seen:]
        self.events.extend(new)
        return new

    def follow_route(self, sumo) -> None:
        """The planned route as SUMO has it now, when it is that (the episode extends it at each
        choice), not a free placement's one edge off it."""
        assert self.driving is not None
        route = list(sumo.vehicle.getRoute(self.vehicle_id))
        if len(route) > 1 or (route and route[0] in self.driving.route):
            self.driving.route = route

    def sample(self, sumo) -> None:
        """The step's sample of the person's driving (manual_measures.py), at SUMO's time now."""
        driving = self.driving
        if driving is None or driving.current is None or not driving.edge or driving.edge.startswith(":"):
            return
        pose = driving.current
        lane = f"{driving.edge}_{driving.lane_index}"
        if lane not in self.shapes:
            self.shapes[lane] = list(sumo.lane.getShape(lane))
        fx, fy = forward(pose.angle)
        centre = (pose.x - fx * driving.length / 2, pose.y - fy * driving.length / 2)
        others = []
        for other in sumo.vehicle.getIDList():
            if other == self.vehicle_id:
                continue
            ox, oy = sumo.vehicle.getPosition(other)
            if math.hypot(ox - pose.x, oy - pose.y) <= TTC_RANGE + 20.0:
                kind = sumo.vehicle.getTypeID(other)
                others.append((ox, oy, sumo.vehicle.getAngle(other), sumo.vehicle.getSpeed(other),
                               sumo.vehicletype.getLength(kind), sumo.vehicletype.getWidth(kind)))
        self.trace.append(Sample(sumo.simulation.getTime(), signed_offset(self.shapes[lane], *centre),
                                 pose.speed, ttc_ahead(pose.x, pose.y, pose.angle, pose.speed,
                                                       driving.width, others)))

    def lane_length(self, sumo, lane: str) -> float:
        if lane not in self.lengths:
            self.lengths[lane] = sumo.lane.getLength(lane)
        return self.lengths[lane]

    def to_hold_point(self, sumo, road: str) -> HoldPoint | None:
        """Where the hold wants the car to stand (None where there is no such road), from where
        SUMO has the ego.

        `road` is the episode's open road: the ego's own, or, once the junction after it is
        chosen (COMMIT_DISTANCE before its end), the next one while the ego is still on the road
        before it or in the junction between. A person who takes over in that window is held at
        the end of the road they are on (HOLD_MARGIN before the junction: its commit point is
        behind them, so no hand-back at it will come), or, in the junction already, at the commit
        point of the road after it."""
        driving = self.driving
        assert driving is not None
        lane = sumo.vehicle.getLaneID(self.vehicle_id)
        if not lane:
            return None
        commit = self.commit_distance + HOLD_MARGIN
        position = sumo.vehicle.getLanePosition(self.vehicle_id)
        rest = self.lane_length(sumo, lane) - position
        route, chain = driving.route, self.chain(road)
        length = self.edge_lengths(sumo)
        if lane.startswith(":"):   # (never the junction after `road`: the episode hands back before it)
            ahead = self.through_junction(sumo, chain, rest)
            return None if ahead is None else HoldPoint(ahead, commit, False)
        edge = sumo.lane.getEdgeID(lane)
        ahead = to_road_end(chain, edge, rest, length)
        if ahead is not None:
            return HoldPoint(ahead, commit, False)
        if chain[0] in route and edge in route[:route.index(chain[0])]:   # on the road before it
            own = None if self.behind is None else to_road_end(self.chain(self.behind), edge, rest, length)
            return HoldPoint(rest if own is None else own, HOLD_MARGIN, True)
        if driving.opposite(sumo, edge):   # back along the oncoming lane, which starts at that junction
            own_road = driving.edge in chain
            return HoldPoint(position, commit if own_road else HOLD_MARGIN, not own_road)
        return None

    def through_junction(self, sumo, chain: tuple[str, ...], rest: float) -> float | None:
        """From a junction `rest` metres before its end to the end of the road whose edges are
        `chain`: a junction inside the road (between two of its edges, on an imported town) or the
        one before it; None when the road is not on the ego's route."""
        assert self.driving is not None
        length = self.edge_lengths(sumo)
        # SUMO's route index stays on the edge before the junction until the ego leaves it
        edges, index = sumo.vehicle.getRoute(self.vehicle_id), sumo.vehicle.getRouteIndex(self.vehicle_id)
        inside = to_road_end(chain, edges[index], rest, length) if 0 <= index < len(edges) else None
        if inside is not None:
            return inside
        if chain[0] not in self.driving.route:
            return None
        return rest + sum(length(edge) for edge in chain)

    def edge_lengths(self, sumo) -> Callable[[str], float]:
        """An edge's length: its lane 0's."""
        return lambda edge: self.lane_length(sumo, f"{edge}_0")

    @property
    def held(self) -> bool:
        """Whether the car is brought to a stand for the hand-back whatever the pedals say: once the
        hold has begun (`hold`, or `guide_back` off its lane) with the car on a lane of its route or
        after a collision (`ManualDriving.may_hand_back`), and once it is stopped off its lane at
        the road's end (`held_off_lane`) or off the road (`stopped_off_road`). Guided back from the
        oncoming lane or off the road it is not: the pedals still drive it (at a creep), or a car
        stopped there could never get back. The station sends no pedals while held, and no steering
        once the car stands (each frame's `held`, harness/live/worker.py). A hand-back ends the
        hold; a takeover starts none."""
        driving = self.driving
        if driving is None:
            return False
        return driving.stranded or self.held_off_lane or (self.holding and driving.may_hand_back)

    def held_controls(self, sumo, road: str) -> Controls:
        """The person's controls under the hold before the junction (see the class and `held`)."""
        driving = self.driving
        assert driving is not None
        point = self.to_hold_point(sumo, road)
        remaining = None if point is None else point.remaining
        now = sumo.simulation.getTime()
        speed = driving.pose.speed
        if not self.holding and point is not None and \
                point.remaining <= hold_distance(speed, point.short_of - HOLD_MARGIN):
            self.holding = True
            kind = "hold" if driving.may_hand_back else "guide_back"
            driving.events.append({"t": now, "type": kind, "remaining": round(point.remaining, 1)})
        if not self.holding:
            return self.controls
        if self.held:   # braking as the assisted hold does ...
            decel = MANUAL.decel
            if point is not None and point.firm:   # ... or harder, as it takes to stop short of it
                room = point.remaining - point.short_of
                decel = driving.params.max_brake if room <= 0.5 else max(decel, speed * speed / (2 * room))
            return replace(self.controls, throttle=0.0, brake=min(decel / driving.params.max_brake, 1.0))
        stopping = speed ** 2 / (2 * driving.params.max_brake)
        if remaining is not None and remaining <= HOLD_MARGIN + stopping:
            self.held_off_lane = True
            driving.events.append({"t": now, "type": "held_off_lane", "remaining": round(remaining, 1)})
            return replace(self.controls, throttle=0.0, brake=1.0)   # (at a creep: stopped at once)
        if speed >= CREEP_SPEED:
            return replace(self.controls, throttle=0.0, brake=max(self.controls.brake, CREEP_BRAKE))
        return self.controls
