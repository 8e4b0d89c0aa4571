"""A person driving the ego by hand, and the hold before their hand-back (live studies).

The rule of the paper's study is that the person hands back before the next junction. In
control, the person drives by hand (`ManualDriving.step`, every step after the takeover): the
pedals set the speed (PEDAL_ACCEL, PEDAL_DECEL per second held; the speed set last holds once the
pedal is released), and SUMO's overtaking through the oncoming lane waits for them to pull out.
A person still in control WARN_DISTANCE before the road's end is warned; the ego then brakes to
wait short of the commit point (HOLD_MARGIN before it, plus its braking distance) until the
hand-back, and SUMO's own driving comes back with it. The inputs come from the person's
`PersonControls` (drivers.py).

A road's end is the end of the last of the SUMO edges it runs along (`to_road_end`): on a built
town a road is one edge named by it, on an imported town a chain of the net's own edges
(harness/simulation/episode_roads.py `EpisodeRoads.chain`), so the warning and the hold come at the
same distance before the junction on both.
"""

from __future__ import annotations

from collections.abc import Callable

from trustroute.harness.simulation.drivers import PersonControls
from trustroute.harness.simulation.driving_style import MANUAL, allow_oncoming_pass, set_speed
from trustroute.harness.simulation.incidents.base import EgoState
from trustroute.harness.simulation.sumo_start import Sumo

WARN_DISTANCE = 100.0      # metres before the road's end: a person in control is told to hand back
HOLD_MARGIN = 5.0          # metres before the commit point where the ego waits for the hand-back
PEDAL_ACCEL = 2.6          # m/s² while the accelerator is held (SUMO's tools/game/racing.py)
PEDAL_DECEL = 4.5          # m/s² while the brake is held


# A road's SUMO edges in driving order (harness/simulation/episode_roads.py `EpisodeRoads.chain`).
RoadChain = Callable[[str], tuple[str, ...]]


def one_edge(road: str) -> tuple[str, ...]:
    """A built town's road: one SUMO edge with the road's id (networks/sumo_net.py)."""
    return (road,)


def to_road_end(chain: tuple[str, ...], edge: str, rest: float,
                length: Callable[[str], float]) -> float | None:
    """Metres to the end of the road whose edges are `chain` from a place `rest` metres before the
    end of `edge` (an edge of the road, or the junction before `edge`): `rest` and the lengths of
    the road's edges after `edge` (the junctions between them not counted, as the episode counts a
    road's length). None when `edge` is not one of the road's."""
    if edge not in chain:
        return None
    return rest + sum(length(later) for later in chain[chain.index(edge) + 1:])


def hold_distance(speed: float, commit_distance: float) -> float:
    """Metres before the road's end where a person still in control at `speed` starts braking to
    wait for the hand-back: the commit point, HOLD_MARGIN, and the braking distance (with a
    second's reaction)."""
    braking = speed * speed / (2.0 * MANUAL.decel) + speed
    return commit_distance + HOLD_MARGIN + braking


class ManualDriving:
    """The person's pedals and pull-out while in control, and the hold before the hand-back, for
    one episode of `vehicle_id`, whose roads are committed `commit_distance` metres before their
    end."""

    def __init__(self, person: PersonControls, vehicle_id: str, commit_distance: float,
                 chain: RoadChain = one_edge) -> None:
        self.person = person
        self.vehicle_id = vehicle_id
        self.commit_distance = commit_distance
        self.chain = chain
        self.by_hand = False               # the person's manual controls are in force
        self.pedal = "release"             # accelerate, brake, or release
        self.steer: str | None = None      # a pull-out ("oncoming") or pull-in ("own") to apply
        self.speed_held = False            # the speed is the person's, not SUMO's car following
        self.previous_time: float | None = None
        self.warned: str | None = None     # the road whose hand-back warning was sent
        self.holding = False               # the ego waits for the hand-back
        self.lengths: dict[str, float] = {}

    def step(self, sumo: Sumo, ego: EgoState, mode: str, road: str) -> None:
        """Every step, after the step's decisions (`mode` the control the ego drives on, `road` the
        open road): the inputs received, the hold, then the pedals."""
        inputs = self.person.manual_inputs()
        if inputs.pedal is not None:
            self.pedal = inputs.pedal
        if inputs.steer is not None:
            self.steer = inputs.steer
        self.hold_for_hand_back(sumo, ego, mode, road)
        self.drive_by_hand(sumo, ego, mode)

    def drive_by_hand(self, sumo: Sumo, ego: EgoState, mode: str) -> None:
        """The person's pedals and pull-out while in control; SUMO's own driving back on the
        hand-back."""
        step = 0.0 if self.previous_time is None else ego.time - self.previous_time
        self.previous_time = ego.time
        manual = mode == MANUAL.name
        vehicle = self.vehicle_id
        if manual != self.by_hand:
            self.by_hand = manual
            allow_oncoming_pass(sumo, vehicle, not manual)   # in control, the person decides the pass
            if not manual and self.speed_held:
                set_speed(sumo, vehicle, None)
            self.pedal, self.steer, self.speed_held = "release", None, False
        if not manual:
            return
        if self.steer is not None:
            allow_oncoming_pass(sumo, vehicle, self.steer == "oncoming")
            self.steer = None
        if self.holding:
            return   # waiting for the hand-back: the pedals do not move the ego on
        if self.pedal != "release":   # the speed set last holds once the pedal is released
            change = PEDAL_ACCEL * step if self.pedal == "accelerate" else -PEDAL_DECEL * step
            set_speed(sumo, vehicle, ego.speed + change)
            self.speed_held = True

    def hold_for_hand_back(self, sumo: Sumo, ego: EgoState, mode: str, road: str) -> None:
        """Warn a person still in control near the road's end; brake to wait short of the commit
        point until they hand back; release the ego on the hand-back."""
        if mode != MANUAL.name:
            self.warned = None   # a later takeover on this road is warned again
            if self.holding:
                set_speed(sumo, self.vehicle_id, None)   # back to the autopilot's own speed
                self.holding = False
            return
        chain = self.chain(road)
        if ego.road not in chain:   # not on the open road (still on the road before it, or in a junction)
            return
        remaining = to_road_end(chain, ego.road, self.lane_length(sumo, ego.lane) - ego.lane_position,
                                lambda edge: self.lane_length(sumo, f"{edge}_0"))
        assert remaining is not None
        if remaining <= WARN_DISTANCE and self.warned != road:
            self.warned = road
            self.person.hand_back_warning(remaining, ego.time)
        if not self.holding and remaining <= hold_distance(ego.speed, self.commit_distance):
            set_speed(sumo, self.vehicle_id, 0.0)
            self.holding = True

    def lane_length(self, sumo: Sumo, lane: str) -> float:
        if lane not in self.lengths:
            self.lengths[lane] = sumo.lane.getLength(lane)
        return self.lengths[lane]
