"""Pedestrian incident: a person at the start of the road who steps onto the crossing early,
late or not at all.

For a road V-W the net has a prioritised crossing at V over V-W and W-V (networks/sumo_net.py).
The person waits on the sidewalk of W-V just before V; as the ego turns into V-W the crossing is
ahead of it. The timing is drawn from the episode's scene generator (docs/scenes.md):
- "early" (`P_EARLY`): the person is there when the incident is injected and steps onto the
  crossing within a second or two, well before the ego arrives; the ego yields.
- "late" (`P_LATE`): the person runs onto the crossing and is in the ego's lane (inserted on
  the crossing, `LATE_BEFORE_LANE` metres before the ego's path) when the ego is only
  `LATE_MARGIN` metres (drawn) beyond the distance it needs to stop with an emergency brake
  (`EMERGENCY_DECEL`, after one `REACTION` step); the smaller the margin, the harder the ego
  brakes and the closer it comes.
- "none" (the rest): the person stands at the kerb and never crosses.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field

from trustroute.harness.incidents.base import EgoState, Scene

KIND = "pedestrian"
TIMINGS = ("early", "late", "none")
P_EARLY = 0.75
P_LATE = 0.10                 # P(none) = 1 - P_EARLY - P_LATE
EARLY_START = (0.0, 2.0)      # metres before the kerb where an early person starts (uniform)
LATE_MARGIN = (3.0, 12.0)     # metres beyond the emergency stopping distance (uniform)
EMERGENCY_DECEL = 9.0         # m/s²: SUMO's default emergency deceleration of a passenger car
REACTION = 0.5                # s: one simulation step before the ego reacts
LATE_BEFORE_LANE = 0.5        # metres: where on the crossing a late person appears, before the ego's path
START_BEFORE_JUNCTION = 1.0   # metres before the end of the opposite sidewalk: the kerb
ARRIVAL_POSITION = 6.0        # metres along the incident road's sidewalk
WALKING_SPEED = 1.2           # m/s
LATE_WALKING_SPEED = 1.6      # m/s: someone who steps out late is in a hurry
WAIT_SECONDS = 600.0          # a person who does not cross stands this long (the road ends first)
MEASURE_NEAR = 40.0           # metres from the crossing: the person's distance is read only this near
PASSED_AFTER = 25.0           # metres into the road: the crossing is behind the ego


@dataclass
class PedestrianIncident:
    road: str
    reverse_road: str
    person_id: str
    timing: str
    margin: float
    kerb: float                    # lane position of the kerb on the opposite sidewalk
    crossing_xy: tuple[float, float]
    crossing: CrossingPath
    kind: str = KIND
    sumo_ids: tuple[str, ...] = field(init=False)
    inserted: bool = False
    stepped_out: float = math.nan  # sim time the person stepped out (late) or was placed (early)

    def __post_init__(self) -> None:
        self.sumo_ids = (self.person_id,)

    def insert(self, sumo, time: float, before_kerb: float, crosses: bool) -> None:
        sumo.person.add(self.person_id, self.reverse_road, max(0.0, self.kerb - before_kerb), depart=-3,
                        typeID="DEFAULT_PEDTYPE")
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
        sumo.person.add(self.person_id, crossing.edge, crossing.start, depart=-3, typeID="DEFAULT_PEDTYPE")
        sumo.person.setSpeed(self.person_id, LATE_WALKING_SPEED)
        sumo.person.appendWalkingStage(self.person_id, list(crossing.walk), crossing.arrival)
        sumo.person.setColor(self.person_id, (255, 140, 0, 255))
        self.inserted = True
        self.stepped_out = time

    def step(self, sumo, ego: EgoState) -> None:
        if self.inserted or self.timing != "late":
            return
        distance = math.dist((ego.x, ego.y), self.crossing_xy)
        stopping = ego.speed * ego.speed / (2 * EMERGENCY_DECEL) + ego.speed * REACTION
        if distance <= stopping + self.margin:
            self.insert_on_crossing(sumo, ego.time)

    def measure(self, sumo, ego: EgoState, monitor) -> None:
        if not self.inserted or self.timing == "none":
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
        return ego.road == self.road and ego.lane_position > PASSED_AFTER

    def remove(self, sumo) -> None:
        # Also reaches an object still waiting for insertion; one already gone raises, and that is fine.
        if self.inserted:
            with contextlib.suppress(sumo.TraCIException):
                sumo.person.remove(self.person_id)

    def details(self) -> str:
        return f"timing={self.timing} margin={self.margin:.2f} stepped_out={self.stepped_out:.1f}"


@dataclass(frozen=True)
class CrossingPath:
    """The crossing at the start of a road as the ego meets it: the point of its path on the
    crossing and a walk over the crossing that starts just before that point."""

    edge: str                        # the crossing's edge id, e.g. ":A_c0"
    conflict: tuple[float, float]    # where the ego's lane centre meets the crossing
    start: float                     # position on the crossing where a late person appears
    walk: tuple[str, ...]            # crossing, walking area, sidewalk
    arrival: float


def crossing_path(sumo, road: str) -> CrossingPath:
    """The crossing over `road` at its start junction (networks/sumo_net.py puts one there)."""
    lane_start = sumo.lane.getShape(f"{road}_1")[0]
    junction = road.split("-")[0]
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
    ends_here = sidewalk_edge.split("-")[1] == junction
    arrival = max(0.0, sumo.lane.getLength(sidewalk) - 2.0) if ends_here else 2.0
    return CrossingPath(edge=edge, conflict=point, start=max(0.0, t * length - LATE_BEFORE_LANE),
                        walk=(edge, walking_area.rsplit("_", 1)[0], sidewalk_edge), arrival=arrival)


def inject(sumo, scene: Scene) -> PedestrianIncident:
    if scene.reverse_road is None:
        raise ValueError(f"pedestrian incident on {scene.road}: the road has no opposite direction")
    u = scene.rng.random()
    drawn = "early" if u < P_EARLY else "late" if u < P_EARLY + P_LATE else "none"
    timing = scene.overrides.get("timing", drawn)
    if timing not in TIMINGS:
        raise ValueError(f"pedestrian timing {timing!r} is not one of {', '.join(TIMINGS)}")
    margin = float(scene.draw("late_margin", lambda rng: rng.uniform(*LATE_MARGIN)))
    before_kerb = float(scene.draw("early_start", lambda rng: rng.uniform(*EARLY_START)))
    kerb = max(0.0, sumo.lane.getLength(f"{scene.reverse_road}_0") - START_BEFORE_JUNCTION)
    crossing = crossing_path(sumo, scene.road)
    incident = PedestrianIncident(road=scene.road, reverse_road=scene.reverse_road,
                                  person_id=f"{scene.prefix}.pedestrian", timing=timing,
                                  margin=margin if timing == "late" else math.nan, kerb=kerb,
                                  crossing_xy=crossing.conflict, crossing=crossing)
    if timing == "early":
        incident.insert(sumo, scene.time, before_kerb, crosses=True)
    elif timing == "none":
        incident.insert(sumo, scene.time, 0.0, crosses=False)
    return incident
