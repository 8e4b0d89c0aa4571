"""An oncoming vehicle timed to meet the ego: used by the truck and the obstacle scenes.

`schedule_oncoming` places a truck on the opposite directed road so that, at its speed, it
reaches the point `meet_at` metres into the ego's road `meet_in` seconds from now. When that
needs more road than the opposite road has (most meetings on Town01's 50-130 m roads), the
truck starts on a road leading into it (`upstream_lane`) and turns in, so it is already in the
simulation, where SUMO's overtaking checks can see it, when the ego decides whether to pull
out; if that road is too short too, it enters at that road's start later. With
`from_upstream=False` (the obstacle scene's rare "unseen" truck) it instead enters at the
opposite road's start later, at the time that keeps the meeting: a truck turning in from a
side road that nobody could see, possibly while the ego is already in the oncoming lane.
`OncomingVehicle` records where and when the two actually passed each other in SUMO
(`met_time`, `met_x`, `met_y`) and feeds the head-on TTC to the road's PerformanceMonitor.

Both checks read the truck from SUMO only when they can matter: the gap between the two
fronts shrinks by at most `MAX_CLOSING` m/s, so while it is large the next read is scheduled
for when it could first come within `WATCH_HORIZON` seconds of a meeting (an exact bound,
not a sampling: the head-on TTC below the horizon and the meeting time are unchanged).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from trustroute.harness.simulation.incidents.base import (
    EgoState,
    Scene,
    VehicleType,
    define_vehicle_type,
    head_on_ttc,
    lane_length,
    remove_vehicle,
    vehicle_on_the_net,
)
from trustroute.harness.simulation.performance import PerformanceMonitor
from trustroute.harness.simulation.sumo_start import Sumo, net_fact

TYPE_ID = "trustroute_truck"
TRUCK_SPEED = 11.0     # m/s (40 km/h): a loaded truck on a 50 km/h town road
TRUCK_LENGTH = 12.0
MAX_CLOSING = 30.0     # m/s: above the ego's 13.89 plus the truck's 11 (both at most at their limits)
WATCH_HORIZON = 3.0    # s: above every head-on TTC limit (harness/simulation/performance.py)
GONE_BEHIND = 60.0     # metres behind the ego after the meeting: the vehicle leaves the simulation
# A head-on standstill: the ego, pulled out into the truck's lane (beside an obstacle it cannot
# return behind), and the truck stand nose to nose before they met. SUMO drives no vehicle
# backwards, so neither would ever move: after BACK_OFF_SECONDS the truck backs off (leaves the
# simulation) and the ego drives on; the head-on TTC measured on the way in stays in its verdict.
STANDING_SPEED = 0.1   # m/s: below this a vehicle stands
NOSE_TO_NOSE = 20.0    # m between the two (their positions, not their fronts)
BACK_OFF_SECONDS = 30.0


TRUCK_TYPE = VehicleType(TYPE_ID, color=(120, 120, 255, 255), vehicle_class="truck", shape_class="truck",
                         length=TRUCK_LENGTH, width=2.5, max_speed=TRUCK_SPEED, accel=1.0)


def define_type(sumo: Sumo) -> None:
    define_vehicle_type(sumo, TRUCK_TYPE)


@dataclass
class OncomingVehicle:
    vehicle_id: str
    route_id: str
    road: str               # the opposite road it drives
    depart_position: float
    insert_time: float      # sim time it enters (now, or later at the road's far end)
    meet_at: float          # metres into the ego's road
    meet_in: float          # seconds after injection, as scheduled
    road_before: str = ""   # the road leading into `road` it starts on ("" when it starts on `road`)
    depart_lane: str = "1"  # SUMO's departLane: lane 1 of a built net, "best" on a real net
    inserted: bool = False
    met_time: float = math.nan
    met_x: float = math.nan
    met_y: float = math.nan
    _gone: bool = False
    _on_road: bool = False
    _next_meeting_check: float = -math.inf
    _next_ttc_check: float = -math.inf
    _read_at: float = math.nan     # the sim time of the step `_where` was read in
    _where: tuple[float, float] | None = None
    _standing_since: float = math.nan   # when the head-on standstill began (NaN: none)
    backed_off: bool = False

    def insert(self, sumo: Sumo) -> None:
        sumo.vehicle.add(self.vehicle_id, self.route_id, typeID=TYPE_ID, depart="now",
                         departLane=self.depart_lane,
                         departPos=f"{self.depart_position:.2f}", departSpeed="max")
        self.inserted = True

    def _position(self, sumo: Sumo, now: float) -> tuple[float, float] | None:
        """Where the vehicle is in the step at `now`: read from SUMO once per step (the meeting
        check and the TTC both read it in the same steps, their schedules being the same bound).
        None also once it has left the simulation, which the failed read tells (`_gone`)."""
        if now != self._read_at:
            self._read_at = now
            try:
                self._where = vehicle_on_the_net(sumo, self.vehicle_id)
            except sumo.TraCIException:
                self._where, self._gone = None, True
        return self._where

    def _quiet_until(self, now: float, gap: float) -> float:
        """The earliest time the gap could come within WATCH_HORIZON seconds of closing."""
        return now + max(0.0, gap - MAX_CLOSING * WATCH_HORIZON) / MAX_CLOSING

    def step(self, sumo: Sumo, ego: EgoState) -> None:
        if not self.inserted:
            if ego.time >= self.insert_time:
                self.insert(sumo)
            return
        if self._gone or ego.time < self._next_meeting_check:
            return
        if not math.isnan(self.met_time):
            self._leave_when_behind(sumo, ego)
            return
        where = self._position(sumo, ego.time)
        if where is None:   # not yet inserted, or gone
            return
        x, y = where
        gap = math.dist(where, (ego.x, ego.y))
        self._next_meeting_check = self._quiet_until(ego.time, gap)
        if self.road_before and not self._on_road:
            # Still on the road leading in or turning: its heading says nothing about the meeting.
            if sumo.vehicle.getRoadID(self.vehicle_id) != self.road:
                return
            self._on_road = True
        angle = math.radians(sumo.vehicle.getAngle(self.vehicle_id))
        # Met: the ego is no longer ahead of the truck along the truck's heading.
        if (ego.x - x) * math.sin(angle) + (ego.y - y) * math.cos(angle) <= 0:
            self.met_time, self.met_x, self.met_y = ego.time, x, y
        else:
            self._back_off_when_stuck(sumo, ego, gap)

    def _back_off_when_stuck(self, sumo: Sumo, ego: EgoState, gap: float) -> None:
        """The truck leaves once it and the ego have stood nose to nose for BACK_OFF_SECONDS
        (its speed is read only while the ego stands close to it)."""
        if ego.speed >= STANDING_SPEED or gap > NOSE_TO_NOSE or \
                sumo.vehicle.getSpeed(self.vehicle_id) >= STANDING_SPEED:
            self._standing_since = math.nan
            return
        if math.isnan(self._standing_since):
            self._standing_since = ego.time
        elif ego.time - self._standing_since >= BACK_OFF_SECONDS:
            self.backed_off = True
            self.remove(sumo)

    def _leave_when_behind(self, sumo: Sumo, ego: EgoState) -> None:
        """After the meeting the vehicle drives away behind the ego, where nothing the ego does
        depends on it: it leaves the simulation once `GONE_BEHIND` metres away (SUMO then has one
        vehicle less to step)."""
        where = self._position(sumo, ego.time)
        if where is None:
            self._gone = True
            return
        gap = math.dist(where, (ego.x, ego.y))
        if gap >= GONE_BEHIND:
            self.remove(sumo)
        else:
            self._next_meeting_check = ego.time + (GONE_BEHIND - gap) / MAX_CLOSING

    def measure(self, sumo: Sumo, ego: EgoState, monitor: PerformanceMonitor) -> None:
        """The head-on TTC of this step, when it can be below WATCH_HORIZON."""
        if not self.inserted or self._gone or ego.time < self._next_ttc_check:
            return
        where = self._position(sumo, ego.time)
        if where is None:
            return
        x, y = where
        self._next_ttc_check = self._quiet_until(ego.time, math.dist((x, y), (ego.x, ego.y)))
        ttc = head_on_ttc(sumo, ego, self.vehicle_id)
        if ttc < WATCH_HORIZON:
            monitor.head_on(ttc)

    def done(self) -> bool:
        """Inserted and out of the simulation again: `step` and `measure` do nothing from now on."""
        return self.inserted and self._gone

    def remove(self, sumo: Sumo) -> None:
        # One known to be out of the simulation (never added, left, or taken out behind the ego)
        # is not asked for: SUMO's refusal is an exception, dearer than the removal itself.
        if self.inserted and not self._gone:
            remove_vehicle(sumo, self.vehicle_id)
        self._where, self._read_at, self._gone = None, math.nan, True

    def details(self) -> str:
        return (f"oncoming={self.vehicle_id} meet_at={self.meet_at:.1f} meet_in={self.meet_in:.1f} "
                f"met_time={self.met_time:.1f} from={self.road_before or self.road}"
                + (" backed_off=yes" if self.backed_off else ""))


TURNS = {"s": 0, "r": 1, "l": 1, "R": 2, "L": 2}   # SUMO link directions, straightest first (no U-turn)


def _lanes(sumo: Sumo, scene: Scene, edge: str) -> list[str]:
    """The lanes of `edge` a truck may come from: lane 1 of a built net, every lane of a real one
    that lets trucks drive (a real net has bus and delivery lanes, and streets closed to trucks)."""
    if scene.end_junction is None:
        return [f"{edge}_1"]
    return [lane for lane in (f"{edge}_{i}" for i in range(sumo.edge.getLaneNumber(edge)))
            if allows_trucks(sumo, lane)]


def allows_trucks(sumo: Sumo, lane: str) -> bool:
    """Whether SUMO lets the oncoming vehicle (a truck) drive on `lane`; SUMO refuses to insert a
    vehicle on a lane closed to its class. Read once per started simulation (net_fact)."""
    return net_fact(("allows trucks", lane),
                    lambda: TRUCK_TYPE.vehicle_class not in sumo.lane.getDisallowed(lane))


def oncoming_possible(sumo: Sumo, scene: Scene) -> bool:
    """Whether an oncoming truck can drive scene.road's opposite lane: the road has one, and it is
    open to trucks (on a real net it may be a bus lane or a street closed to trucks)."""
    return (scene.reverse_road is not None
            and allows_trucks(sumo, f"{scene.reverse_road}_{scene.reverse_lane}"))


def upstream_lane(sumo: Sumo, scene: Scene) -> str | None:
    """The lane of the road that leads into scene.reverse_road at the junction where the ego's road
    ends, other than the ego's own road, without a U-turn: the straightest, then the longest, then
    by id. Where an oncoming truck comes from. Read once per started simulation (net_fact)."""
    return net_fact(("upstream lane", scene.ends_at, scene.road, scene.reverse_road, scene.end_junction),
                    lambda: _upstream_lane(sumo, scene))


def _upstream_lane(sumo: Sumo, scene: Scene) -> str | None:
    roads = []
    for edge in sumo.junction.getIncomingEdges(scene.ends_at):
        if edge.startswith(":") or edge == scene.road:
            continue
        for lane in _lanes(sumo, scene, edge):
            for link in sumo.lane.getLinks(lane):
                if link[0].rsplit("_", 1)[0] == scene.reverse_road and link[6] in TURNS:
                    roads.append((TURNS[link[6]], -lane_length(sumo, lane), edge, lane))
    return min(roads)[3] if roads else None


def schedule_oncoming(sumo: Sumo, scene: Scene, meet_at: float, meet_in: float, vehicle_id: str,
                      speed: float = TRUCK_SPEED, from_upstream: bool = True) -> OncomingVehicle:
    """A truck on scene.reverse_road timed to pass `meet_at` (ego's road coordinates) in `meet_in` s,
    starting on the road leading into it when the reverse road alone is too short for that
    (unless `from_upstream` is False: then it turns in unseen, entering at the road's start later).
    The scene's road must have an opposite road (ValueError otherwise)."""
    road = scene.reverse_road
    if road is None:
        raise ValueError(f"oncoming vehicle on {scene.road}: the road has no opposite direction")
    reverse_length = lane_length(sumo, f"{road}_{scene.reverse_lane}")
    meeting_on_reverse = max(0.0, reverse_length - meet_at)
    depart = meeting_on_reverse - speed * max(meet_in, 0.0)
    roads = [road]
    before = ""
    before_lane = upstream_lane(sumo, scene) if depart < 0 and from_upstream else None
    if before_lane is not None:
        before = before_lane.rsplit("_", 1)[0]
        # The junction's internal lane adds its length to the way; the turn's slowing is not
        # modelled (met_time records when the two really passed each other).
        before_length = lane_length(sumo, before_lane)
        inside = net_fact(("turn length", before_lane, road), lambda: next(
            (sumo.lane.getLength(link[4]) for link in sumo.lane.getLinks(before_lane)
             if link[0].rsplit("_", 1)[0] == road and link[4]), 0.0))
        depart += before_length + inside
        roads = [before, road]
    delay = 0.0 if depart >= 0 else -depart / speed
    route_id = f"{vehicle_id}_route"
    sumo.route.add(route_id, roads)
    vehicle = OncomingVehicle(vehicle_id=vehicle_id, route_id=route_id, road=road,
                              depart_position=max(depart, 0.0), insert_time=scene.time + delay,
                              meet_at=meet_at, meet_in=meet_in, road_before=before,
                              depart_lane="1" if scene.end_junction is None else "best")
    if delay == 0.0:
        vehicle.insert(sumo)
    return vehicle
