"""Pedestrian incident: a person at the start of the road who steps onto the crossing early,
late or not at all.

For a road V-W the net has a prioritised crossing at V over V-W and W-V (networks/sumo_net.py).
The person waits on the sidewalk of W-V just before V; as the ego turns into V-W the crossing is
ahead of it. The timing is drawn from the episode's scene generator (docs/scenes.md):
- "early" (`P_EARLY`): the person is there when the incident is injected and steps onto the
  crossing within a second or two, well before the ego arrives; the ego yields.
- "late" (`P_LATE`): the person runs onto the crossing (inserted on it, `LATE_BEFORE_LANE`
  metres before the ego's path) when the ego needs a drawn deceleration
  (`LATE_DECELERATION`) to stop before the crossing, and never so late that it would need
  more than `SAFE_NEED` when the AV sees the person (one step later).
- "none" (the rest): the person stands at the kerb and never crosses.

The AV perceives the person (`PedestrianIncident.guard`, from SUMO's person state): SUMO's
junction model yields to a person on a crossing only with its comfortable deceleration and
ignores one it cannot stop for that way, so while the person is on the crossing in or walking
into the ego's path, the AV brakes to stop `STOP_BEFORE_PATH` metres before the path itself:
gently (the deceleration needed) when that is within the ego's comfortable deceleration,
otherwise with automatic emergency braking (`EMERGENCY_DECEL`, held until the path is clear).
An emergency brake is above the 5 m/s² deceleration limit: a measured `fail`, without a collision.
On an imported town's own net the crossing is the net's own at the start of the incident's edge;
where there is none the scene is not placed (`inject` returns None, docs/scenes.md "Real maps").
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field

from trustroute.harness.simulation.driving_style import SAFE_SPEED_MODE
from trustroute.harness.simulation.incidents.base import (
    EgoState,
    Scene,
    VehicleType,
    define_vehicle_type,
    lane_length,
)
from trustroute.harness.simulation.sumo_start import net_fact
from trustroute.networks.road import Road

KIND = "pedestrian"
TIMINGS = ("early", "late", "none")
P_EARLY = 0.75
P_LATE = 0.03                 # P(none) = 1 - P_EARLY - P_LATE (docs/scenes.md: why 0.03)
EARLY_START = (0.0, 2.0)      # metres before the kerb where an early person starts (uniform)
LATE_DECELERATION = (1.0, 6.0)  # m/s²: what the ego needs to stop when a late person steps out (uniform)
SAFE_NEED = 8.5               # m/s²: a late person never appears when the ego would need more than this
EMERGENCY_DECEL = 9.0         # m/s²: SUMO's default emergency deceleration of a passenger car
EMERGENCY_SPEED_MODE = 27     # SUMO speed mode 31 without "regard maximum deceleration"
STOP_BEFORE_PATH = 2.5        # metres: the AV stops this far before the ego's path on the crossing
                              # (half of netconvert's 4 m crossing width and 0.5 m)
PATH_HALF_WIDTH = 2.0         # metres along the crossing either side of the ego's lane centre: in its path
LOOKOUT = 4.0                 # metres: a person walking towards the ego's path this close enters it
LATE_BEFORE_LANE = 0.5        # metres: where on the crossing a late person appears, before the ego's path
START_BEFORE_JUNCTION = 1.0   # metres before the end of the opposite sidewalk: the kerb
ARRIVAL_POSITION = 6.0        # metres along the incident road's sidewalk
WALKING_SPEED = 1.2           # m/s
LATE_WALKING_SPEED = 1.6      # m/s: someone who steps out late is in a hurry
# SUMO's default person, walking at exactly the speed the scene sets (no speed deviation drawn)
PERSON_TYPE = VehicleType("trustroute_pedestrian", color=(255, 140, 0, 255), base="DEFAULT_PEDTYPE")
WAIT_SECONDS = 600.0          # a person who does not cross stands this long (the road ends first)
MEASURE_NEAR = 40.0           # metres from the crossing: the person's distance is read only this near
PASSED_AFTER = 25.0           # metres into the road: the crossing is behind the ego (at most half
                              # the watched stretch: Town01's A-B is watched for 15 m)


def define_type(sumo) -> None:
    define_vehicle_type(sumo, PERSON_TYPE)


@dataclass
class PedestrianIncident:
    road: str
    reverse_road: str
    person_id: str
    timing: str
    late_deceleration: float
    kerb: float                    # lane position of the kerb on the opposite sidewalk
    crossing_xy: tuple[float, float]
    crossing: CrossingPath
    ego_id: str = "ego"
    ego_accel: float = 2.6         # m/s²: the ego's maximum acceleration (read from SUMO)
    road_speed: float = 13.89
    step_length: float = 0.5         # s: the simulation step
    comfortable_decel: float = 4.5   # m/s²: the ego's own braking when the person appears (read from SUMO)
    kind: str = KIND
    sumo_ids: tuple[str, ...] = field(init=False)
    inserted: bool = False
    stepped_out: float = math.nan  # sim time the person stepped out (late) or was placed (early)
    braking: bool = False          # the AV controls the ego's speed to stop for the person
    emergency: bool = False        # ... with its emergency deceleration
    restore_decel: float = math.nan
    emergency_time: float = math.nan   # sim time the ego's emergency braking was armed
    cleared: bool = False
    left: bool = False                 # taken out of the simulation
    seen_needing: float = math.nan     # m/s² the ego needed to stop when the AV first saw the person
    last_offset: float = math.inf      # the person's last distance along the crossing to the ego's path
    passed_after: float = PASSED_AFTER  # metres into the road: past the crossing

    def __post_init__(self) -> None:
        self.sumo_ids = (self.person_id,)

    def insert(self, sumo, time: float, before_kerb: float, crosses: bool) -> None:
        sumo.person.add(self.person_id, self.reverse_road, max(0.0, self.kerb - before_kerb), depart=-3,
                        typeID=PERSON_TYPE.type_id)
        sumo.person.setSpeed(self.person_id, WALKING_SPEED)
        if crosses:
            sumo.person.appendWalkingStage(self.person_id, [self.reverse_road, self.road], ARRIVAL_POSITION)
        else:
            sumo.person.appendWaitingStage(self.person_id, WAIT_SECONDS, "waits at the kerb")
        sumo.person.setColor(self.person_id, (255, 140, 0, 255))
        self.inserted = True
        self.stepped_out = time

    def position(self, sumo) -> tuple[float, float] | None:
        if not self.inserted:
            return None
        try:
            return tuple(sumo.person.getPosition(self.person_id))
        except sumo.TraCIException:
            return None

    def insert_on_crossing(self, sumo, time: float) -> None:
        crossing = self.crossing
        sumo.person.add(self.person_id, crossing.edge, crossing.start, depart=-3, typeID=PERSON_TYPE.type_id)
        sumo.person.setSpeed(self.person_id, LATE_WALKING_SPEED)
        sumo.person.appendWalkingStage(self.person_id, list(crossing.walk), crossing.arrival)
        sumo.person.setColor(self.person_id, (255, 140, 0, 255))
        self.inserted = True
        self.stepped_out = time

    def stop_distance(self, ego: EgoState) -> float:
        """Metres from the ego's front to where the AV stops for a person on the crossing."""
        return math.dist((ego.x, ego.y), self.crossing_xy) - STOP_BEFORE_PATH

    def needed_deceleration(self, speed: float, gap: float) -> float:
        return speed * speed / (2 * gap) if gap > 0 else math.inf

    def steps_out_now(self, ego: EgoState) -> bool:
        """Step out in this step when the ego already needs the drawn deceleration to stop, or
        when waiting one more step could leave it, at its maximum acceleration, needing more
        than SAFE_NEED when the AV sees the person (so the emergency brake always stops it)."""
        gap = self.stop_distance(ego)
        if self.needed_deceleration(ego.speed, gap) >= self.late_deceleration:
            return True
        top = max(ego.speed, self.road_speed)    # the autopilot does not drive above the limit
        v1 = min(ego.speed + self.ego_accel * self.step_length, top)
        v2 = min(v1 + self.ego_accel * self.step_length, top)
        return self.needed_deceleration(v2, gap - (v1 + v2) * self.step_length) > SAFE_NEED

    def step(self, sumo, ego: EgoState) -> None:
        if not self.inserted:
            if self.timing != "late":
                return
            # The person appears on the crossing in the next step, and the AV sees them then.
            if self.steps_out_now(ego):
                self.insert_on_crossing(sumo, ego.time)
            return
        if self.timing != "none" and not self.cleared:
            self.guard(sumo, ego)
        if not self.left and self.is_passed(sumo, ego):
            # Behind the ego the person can no longer meet it: they leave the simulation (SUMO
            # then has no person to step), the runner's `remove` at the road's end is a no-op.
            self.remove(sumo)

    def guard(self, sumo, ego: EgoState) -> None:
        """The AV's perception of the person (SUMO's junction model does not brake harder than
        the comfortable deceleration for a person, and ignores one it cannot stop for that way):
        while the person is on the crossing in or about to enter the ego's path and the ego is
        still before the crossing, the AV brakes to stop at the crossing, up to its emergency
        deceleration, and holds until the person has left its path."""
        gap = self.stop_distance(ego)
        passed = ego.road == self.road and ego.lane_position > 0.0
        if passed or gap > MEASURE_NEAR:
            if passed:
                self.release(sumo)
                self.cleared = True
            return
        try:
            where = sumo.person.getRoadID(self.person_id)
            along = sumo.person.getLanePosition(self.person_id)
        except sumo.TraCIException:
            self.release(sumo)
            return
        offset = abs(along - self.crossing.conflict_position) if where == self.crossing.edge else math.inf
        approaching = offset < self.last_offset
        self.last_offset = offset
        in_path = offset <= PATH_HALF_WIDTH or (approaching and offset <= LOOKOUT)
        if not in_path:
            self.release(sumo)
            return
        speed = ego.speed
        needed = self.needed_deceleration(speed, gap)
        if math.isnan(self.seen_needing):
            self.seen_needing = needed
        if not self.emergency and needed > self.comfortable_decel:
            # Automatic emergency braking: full braking once triggered, held until the path is clear.
            self.emergency = True
            self.emergency_time = ego.time
            sumo.vehicle.setSpeedMode(self.ego_id, EMERGENCY_SPEED_MODE)
        decel = EMERGENCY_DECEL if self.emergency else needed
        self.braking = True
        sumo.vehicle.setSpeed(self.ego_id, max(0.0, speed - decel * self.step_length))

    def release(self, sumo) -> None:
        if self.braking:
            sumo.vehicle.setSpeed(self.ego_id, -1.0)
            if self.emergency:
                sumo.vehicle.setSpeedMode(self.ego_id, SAFE_SPEED_MODE)
            self.braking = self.emergency = False

    def measure(self, sumo, ego: EgoState, monitor) -> None:
        # A person taken out (`step`, once behind the ego) is not asked for: SUMO would refuse
        # with an exception, dearer than a read.
        if not self.inserted or self.timing == "none" or self.left:
            return
        # Only near the crossing can the ego come close to a person on it (no SUMO call otherwise).
        if math.dist((ego.x, ego.y), self.crossing_xy) > MEASURE_NEAR:
            return
        try:
            where = sumo.person.getRoadID(self.person_id)
        except sumo.TraCIException:
            return
        if where.startswith(":") and "_c" in where:   # on the crossing
            monitor.pedestrian_distance(math.dist((ego.x, ego.y), sumo.person.getPosition(self.person_id)))

    def is_passed(self, sumo, ego: EgoState) -> bool:
        return ego.road == self.road and ego.lane_position > self.passed_after

    def done(self) -> bool:
        # Taken out, and the guard released (or never needed): `step` and `measure` do nothing.
        return self.left and (self.cleared or self.timing == "none")

    def remove(self, sumo) -> None:
        # Also reaches an object still waiting for insertion; one already gone raises, and that is fine.
        if self.inserted and not self.left:
            self.left = True
            with contextlib.suppress(sumo.TraCIException):
                sumo.person.remove(self.person_id)

    def details(self) -> str:
        return (f"timing={self.timing} late_deceleration={self.late_deceleration:.2f} "
                f"stepped_out={self.stepped_out:.1f} seen_needing={self.seen_needing:.2f} "
                f"emergency_brake={self.emergency_time:.1f}")


@dataclass(frozen=True)
class CrossingPath:
    """The crossing at the start of a road as the ego meets it: the point of its path on the
    crossing and a walk over the crossing that starts just before that point."""

    edge: str                        # the crossing's edge id, e.g. ":A_c0"
    conflict: tuple[float, float]    # where the ego's lane centre meets the crossing
    conflict_position: float         # the same point as a position along the crossing
    start: float                     # position on the crossing where a late person appears
    walk: tuple[str, ...]            # crossing, walking area, sidewalk
    arrival: float


def crossing_path(sumo, road: str, lane: int = 1, junction: str | None = None) -> CrossingPath:
    """The crossing over `road` at its start junction (networks/sumo_net.py puts one there; on a
    real net, `junction` names the edge's start junction and `lane` its driving lane). Static
    geometry: looked up once per started simulation (sumo_start.net_fact). ValueError: no
    crossing."""
    return net_fact(("crossing", road, lane, junction), lambda: _find_crossing(
        sumo, road, sumo.lane.getShape(f"{road}_{lane}")[0], junction))


def _find_crossing(sumo, road: str, lane_start: tuple[float, float], junction: str | None) -> CrossingPath:
    real = junction is not None
    junction = junction if junction is not None else Road.parse(road).from_junction
    best = None
    for edge in sumo.junction.getOutgoingEdges(junction):
        if not edge.startswith(f":{junction}_c"):
            continue
        (x0, y0), (x1, y1) = sumo.lane.getShape(f"{edge}_0")[0], sumo.lane.getShape(f"{edge}_0")[-1]
        dx, dy = x1 - x0, y1 - y0
        t = ((lane_start[0] - x0) * dx + (lane_start[1] - y0) * dy) / (dx * dx + dy * dy)
        t = min(max(t, 0.0), 1.0)
        point = (x0 + t * dx, y0 + t * dy)
        distance = math.dist(point, lane_start)
        if best is None or distance < best[0]:
            best = (distance, edge, point, t)
    if best is None:
        raise ValueError(f"pedestrian incident on {road}: the net has no crossing at {junction}")
    _, edge, point, t = best
    length = sumo.lane.getLength(f"{edge}_0")
    walking_area = sumo.lane.getLinks(f"{edge}_0")[0][0]     # the crossing leads to one walking area
    sidewalk = next(link[0] for link in sumo.lane.getLinks(walking_area) if not link[0].startswith(":"))
    sidewalk_edge = sidewalk.rsplit("_", 1)[0]
    ends_at = sumo.edge.getToJunction(sidewalk_edge) if real else Road.parse(sidewalk_edge).to_junction
    ends_here = ends_at == junction
    arrival = max(0.0, sumo.lane.getLength(sidewalk) - 2.0) if ends_here else 2.0
    return CrossingPath(edge=edge, conflict=point, conflict_position=t * length,
                        start=max(0.0, t * length - LATE_BEFORE_LANE),
                        walk=(edge, walking_area.rsplit("_", 1)[0], sidewalk_edge), arrival=arrival)


def inject(sumo, scene: Scene) -> PedestrianIncident | None:
    """The scene on a built net; on a real net (Scene.end_junction set) None where the edge's start
    junction has no crossing."""
    if scene.reverse_road is None:
        raise ValueError(f"pedestrian incident on {scene.road}: the road has no opposite direction")
    u = scene.rng.random()
    drawn = "early" if u < P_EARLY else "late" if u < P_EARLY + P_LATE else "none"
    timing = scene.overrides.get("timing", drawn)
    if timing not in TIMINGS:
        raise ValueError(f"pedestrian timing {timing!r} is not one of {', '.join(TIMINGS)}")
    late_deceleration = float(scene.draw("late_deceleration", lambda rng: rng.uniform(*LATE_DECELERATION)))
    before_kerb = float(scene.draw("early_start", lambda rng: rng.uniform(*EARLY_START)))
    kerb = max(0.0, lane_length(sumo, f"{scene.reverse_road}_0") - START_BEFORE_JUNCTION)
    if scene.end_junction is None:
        crossing = crossing_path(sumo, scene.road)
    else:
        try:
            crossing = crossing_path(sumo, scene.road, scene.lane, scene.start_junction)
        except (ValueError, StopIteration, IndexError):   # no crossing, or one not led to a sidewalk
            return None
    incident = PedestrianIncident(road=scene.road, reverse_road=scene.reverse_road,
                                  person_id=f"{scene.prefix}.pedestrian", timing=timing,
                                  late_deceleration=late_deceleration if timing == "late" else math.nan,
                                  kerb=kerb,
                                  crossing_xy=crossing.conflict, crossing=crossing, ego_id=scene.ego_id,
                                  ego_accel=sumo.vehicle.getAccel(scene.ego_id), road_speed=scene.road_speed,
                                  comfortable_decel=sumo.vehicle.getDecel(scene.ego_id),
                                  step_length=scene.step_length,
                                  passed_after=min(PASSED_AFTER, 0.5 * scene.watched))
    if timing == "early":
        incident.insert(sumo, scene.time, before_kerb, crosses=True)
    elif timing == "none":
        incident.insert(sumo, scene.time, 0.0, crosses=False)
    return incident
