"""Continuous manual driving: the kinematic bicycle model, and the ego placed in SUMO at its pose
(into the oncoming lane and back, off the road, into a parked truck) on the Town01 net."""

from __future__ import annotations

import math

import pytest

from trustroute.harness.simulation.episode import COMMIT_DISTANCE
from trustroute.harness.simulation.manual_driving import HOLD_MARGIN, hold_distance
from trustroute.harness.simulation.vehicle_model import (
    MODEL_RATE,
    Controls,
    Pose,
    VehicleParams,
    corners,
    integrate,
    overlaps,
)
from trustroute.harness.simulation.wheel_driving import CREEP_SPEED, ManualDriving, Wheel, restore_route

NO_DRAG = VehicleParams(rolling=0.0, drag=0.0)


def test_straight_at_constant_speed_moves_along_the_heading():
    after = integrate(Pose(0.0, 0.0, 90.0, 10.0), Controls(), 2.0, NO_DRAG)   # east at 10 m/s
    assert (after.x, after.y, after.angle, after.speed) == pytest.approx((20.0, 0.0, 90.0, 10.0), abs=1e-9)


def test_a_held_steering_angle_turns_on_the_bicycle_models_circle():
    params = NO_DRAG
    steer = 0.5
    radius = params.wheelbase / math.tan(math.radians(steer * params.max_wheel_angle))   # of the rear axle
    quarter = (math.pi / 2) * radius / 8.0
    after = integrate(Pose(0.0, 0.0, 0.0, 8.0), Controls(steer=steer), quarter, params)
    assert after.angle == pytest.approx(90.0, abs=0.01)   # right: clockwise, from north to east
    left = integrate(Pose(0.0, 0.0, 0.0, 8.0), Controls(steer=-steer), quarter, params)
    assert left.angle == pytest.approx(270.0, abs=0.01)
    # the rear axle went a quarter circle: from (0, -to_rear) to (radius, radius - to_rear)
    to_rear = params.wheelbase + params.front_overhang
    rear = (after.x - to_rear, after.y)
    assert rear == pytest.approx((radius, radius - to_rear), abs=0.05)


def test_pedals_accelerate_and_brake_to_a_stop_without_reversing():
    params = NO_DRAG
    faster = integrate(Pose(0.0, 0.0, 0.0, 0.0), Controls(throttle=1.0), 2.0, params)
    assert faster.speed == pytest.approx(2 * params.max_accel)
    stopped = integrate(Pose(0.0, 0.0, 0.0, 10.0), Controls(brake=1.0), 3.0, params)
    assert stopped.speed == 0.0
    assert stopped.y == pytest.approx(10.0 ** 2 / (2 * params.max_brake), abs=0.1)
    assert Controls(steer=5.0, throttle=-1.0, brake=float("nan")).clamped() == Controls(1.0, 0.0, 0.0)


def test_the_model_is_integrated_at_its_rate_whatever_the_step():
    # held controls: one 0.5 s call is the same as 25 calls of 1/MODEL_RATE s
    pose = Pose(3.0, 4.0, 30.0, 7.0)
    controls = Controls(steer=0.3, throttle=0.4)
    whole = integrate(pose, controls, 0.5)
    for _ in range(int(0.5 * MODEL_RATE)):
        pose = integrate(pose, controls, 1.0 / MODEL_RATE)
    assert [whole.x, whole.y, whole.angle, whole.speed] == pytest.approx(
        [pose.x, pose.y, pose.angle, pose.speed])


def test_footprints_overlap_only_when_they_touch():
    ego = corners(0.0, 0.0, 0.0, 4.5, 1.8)
    assert overlaps(ego, corners(0.0, -0.5, 180.0, 4.5, 1.8))       # head on, fronts 0.5 m into each other
    assert not overlaps(ego, corners(0.0, 0.5, 180.0, 4.5, 1.8))     # head on, 0.5 m apart
    assert overlaps(ego, corners(0.0, 3.0, 0.0, 4.5, 1.8))           # into the back of the one ahead
    assert not overlaps(ego, corners(2.0, 0.0, 0.0, 4.5, 1.8))       # side by side, 0.2 m apart
    assert overlaps(ego, corners(1.5, 0.0, 45.0, 4.5, 1.8))


@pytest.fixture(scope="module")
def net():
    from trustroute.harness.study.config import study_config_from_dict
    from trustroute.harness.study.context import study_context
    from trustroute.networks.sumo_net import build_net

    config = study_config_from_dict({"study": {"participants": 1, "seed": 1, "engine": "sumo",
                                               "specs": ["phi1"], "conditions": ["free"]}})
    return build_net(study_context(config).town).path


def park_truck(sumo, position: float, width: float | None = None) -> None:
    """A 12 m truck, "parked", standing in the oncoming lane (E-A) `position` metres into it."""
    sumo.vehicletype.copy("DEFAULT_VEHTYPE", "truck")
    sumo.vehicletype.setLength("truck", 12.0)
    if width is not None:
        sumo.vehicletype.setWidth("truck", width)
    sumo.route.add("against", ["E-A"])
    sumo.vehicle.add("parked", "against", typeID="truck", departPos=str(position), departLane="1")
    sumo.vehicle.setSpeedMode("parked", 0)
    sumo.vehicle.setSpeed("parked", 0.0)


def drive(net, program, obstacle=None):
    """The ego on A-E (a long straight stretch with an oncoming lane) driven by `program`: a list of
    (seconds, Controls); SUMO steps 0.1 s. Returns (trace of (time, x, y, lane, route), driving)."""
    from trustroute.harness.simulation.sumo_start import SumoConfig, fresh_session

    with fresh_session(net, 1, SumoConfig(step_length=0.1)) as sumo:
        sumo.route.add("planned", ["A-E"])
        sumo.vehicle.add("ego", "planned", departPos="10", departSpeed="8", departLane="1")
        if obstacle is not None:
            park_truck(sumo, obstacle, width=2.5)
        sumo.simulationStep()
        driving = ManualDriving.take_over(sumo, "ego")
        trace = []
        for seconds, controls in program:
            for _ in range(round(seconds / 0.1)):
                driving.step(sumo, controls, 0.1)
                sumo.simulationStep()
                x, y = sumo.vehicle.getPosition("ego")
                trace.append((sumo.simulation.getTime(), x, y, sumo.vehicle.getLaneID("ego"),
                              tuple(sumo.vehicle.getRoute("ego")), driving.may_hand_back,
                              sumo.vehicle.getSpeed("ego")))
        driving.observe(sumo, sumo.simulation.getTime())
    return trace, driving


def test_a_person_steers_into_the_oncoming_lane_and_back_and_the_route_is_kept(net):
    cruise = Controls(throttle=0.1)
    left, right = Controls(steer=-0.25, throttle=0.1), Controls(steer=0.25, throttle=0.1)
    # out (left, then straighten), along the oncoming lane, back (right, then straighten): 7 s, 56 m
    trace, driving = drive(net, [(0.5, cruise), (1.0, left), (1.0, right), (1.5, cruise), (1.0, right),
                                 (1.0, left), (1.0, cruise)])
    lanes = [lane for _, _, _, lane, *_ in trace]
    assert "E-A_1" in lanes and lanes[-1] == "A-E_1", lanes
    first, last = lanes.index("E-A_1"), len(lanes) - 1 - lanes[::-1].index("E-A_1")
    assert all(lane == "E-A_1" for lane in lanes[first:last + 1])   # one pass, no flicker
    assert trace[-1][4] == ("A-E",)                                   # the planned route again
    # no hand-back while passing (the rule reads where the previous step put the ego)
    assert not any(step[5] for step in trace[first + 1:last + 2])
    assert trace[-1][5]
    times = [t for t, *_ in trace]
    assert max(b - a for a, b in zip(times, times[1:], strict=False)) == pytest.approx(0.1)   # 10 Hz in SUMO
    # the lateral movement: the ego's centre left its lane by a lane's width and came back
    assert [event["type"] for event in driving.events] == ["oncoming", "own_lane"]
    xs = [x for _, x, *_ in trace]
    assert xs == sorted(xs, reverse=True)   # westwards all along: no teleport, no jump back
    steps = [math.hypot(b[1] - a[1], b[2] - a[2]) for a, b in zip(trace, trace[1:], strict=False)]
    assert max(steps) < 1.5   # at about 8 m/s: at most 0.8 m per 0.1 s step and nothing more


def test_steering_into_a_parked_truck_is_a_collision_and_stops_the_car(net):
    # a truck stands in the oncoming lane 20 m ahead (its front 29 m before the end of E-A)
    program = [(1.0, Controls(steer=-0.25, throttle=0.3)), (1.0, Controls(steer=0.25, throttle=0.3)),
               (3.0, Controls(throttle=0.3))]
    trace, driving = drive(net, program, obstacle=470.0)
    collisions = [event for event in driving.events if event["type"] == "collision"]
    assert [event["object"] for event in collisions] == ["parked"] and collisions[0]["speed"] > 5.0
    assert driving.pose.speed == 0.0   # stopped at the crash, and standing against the truck since
    crash = next(i for i, step in enumerate(trace) if step[0] >= collisions[0]["t"])
    assert {(x, y) for _, x, y, *_ in trace[crash + 1:]} == {trace[crash + 1][1:3]}
    # and SUMO has it at rest too (its speed is what the kinematics table logs)
    assert {step[6] for step in trace[crash + 1:]} == {0.0}


def test_leaving_the_road_is_an_event_and_sumo_keeps_the_ego_on_its_route(net):
    program = [(1.2, Controls(steer=0.3, throttle=0.1)), (1.2, Controls(steer=-0.3, throttle=0.1)),
               (1.0, Controls(throttle=0.1))]
    trace, driving = drive(net, program)
    assert [event["type"] for event in driving.events][:1] == ["off_road"]
    assert {lane for _, _, _, lane, *_ in trace} == {"A-E_1"} and trace[-1][4] == ("A-E",)
    assert driving.where == "off_road" and not trace[-1][5]   # no hand-back off the road


def test_restoring_the_planned_route_keeps_an_extension_the_episode_made_meanwhile(net):
    from trustroute.harness.simulation.sumo_start import SumoConfig, fresh_session

    with fresh_session(net, 1, SumoConfig(step_length=0.1)) as sumo:
        sumo.route.add("planned", ["A-E"])
        sumo.vehicle.add("ego", "planned", departPos="100", departSpeed="8", departLane="1")
        sumo.simulationStep()
        assert restore_route(sumo, "ego", ["A-E", "E-D"])   # a free placement had cut it: given back
        assert sumo.vehicle.getRoute("ego") == ("A-E", "E-D")
        assert restore_route(sumo, "ego", ["A-E"])   # planned before the choice: the extension stays
        assert sumo.vehicle.getRoute("ego") == ("A-E", "E-D")
        assert not restore_route(sumo, "ego", ["E-D"])   # not on the route given: nothing to restore


def drive_to_the_junction(net, program, start=418.0):
    """A person driving the ego by `Wheel` (the live episode's hook) towards the end of A-E, the
    episode's open road: `program` as in `drive`, then a hand-back and 3 s of SUMO's driving.
    Returns (trace of (time, lane, distance to A-E's end by the model, model speed, may hand back),
    SUMO's trace after the hand-back (lane, speed, route), wheel)."""
    from trustroute.harness.simulation.sumo_start import SumoConfig, fresh_session

    with fresh_session(net, 1, SumoConfig(step_length=0.1)) as sumo:
        sumo.route.add("planned", ["A-E", "E-D"])
        sumo.vehicle.add("ego", "planned", departPos=str(start), departSpeed="8", departLane="1")
        sumo.simulationStep()
        end = sumo.lane.getShape("A-E_1")[-1]
        wheel = Wheel("ego", COMMIT_DISTANCE)
        trace = []
        for seconds, controls in program:
            for _ in range(round(seconds / 0.1)):
                wheel.step(sumo, True, "A-E")
                wheel.controls = controls   # (a takeover starts from released controls)
                sumo.simulationStep()
                pose = wheel.driving.pose
                trace.append((sumo.simulation.getTime(), sumo.vehicle.getLaneID("ego"),
                              math.hypot(pose.x - end[0], pose.y - end[1]), pose.speed, wheel.may_hand_back))
        after = []
        for _ in range(30):
            wheel.step(sumo, False, "A-E")
            sumo.simulationStep()
            after.append((sumo.vehicle.getLaneID("ego"), sumo.vehicle.getSpeed("ego"),
                          tuple(sumo.vehicle.getRoute("ego"))))
    return trace, after, wheel


def test_a_person_in_their_lane_is_held_before_the_junction_until_the_hand_back(net):
    # throttle held all the way: the car still stops short of the commit point's margin
    trace, after, wheel = drive_to_the_junction(net, [(12.0, Controls(throttle=0.5))])
    kinds = [event["type"] for event in wheel.events]
    assert kinds == ["hold"], kinds
    hold = wheel.events[0]
    speed_then = next(speed for t, _, _, speed, _ in trace if t >= hold["t"])
    assert hold["remaining"] <= hold_distance(speed_then, COMMIT_DISTANCE) + 1.0
    stopped = [step for step in trace if step[3] == 0.0]
    assert stopped and stopped[0][0] < trace[-1][0] - 3.0   # standing for seconds, throttle held
    assert {round(step[2], 3) for step in stopped} == {round(stopped[0][2], 3)}
    assert stopped[0][2] > HOLD_MARGIN and all(step[4] for step in stopped)
    assert {lane for lane, *_ in after} == {"A-E_1"} and after[-1][1] > 1.0   # the autopilot drives on


def test_a_person_in_the_oncoming_lane_is_guided_back_and_stopped_short_of_the_junction(net):
    # out into the oncoming lane and along it (the lanes bend 3 degrees left on the way)
    out = [(1.0, Controls(steer=-0.25, throttle=0.3)), (0.9, Controls(steer=0.25, throttle=0.3))]
    trace, after, wheel = drive_to_the_junction(net, [*out, (22.0, Controls(throttle=0.6))])
    kinds = [event["type"] for event in wheel.events]
    assert kinds == ["oncoming", "guide_back", "held_off_lane"], kinds
    guided, held = wheel.events[1]["t"], wheel.events[2]["t"]
    # throttle held: no faster than a creep once guided back (but for the first step's braking)
    creeping = [speed for t, _, _, speed, _ in trace if t > guided + 3.0 and t <= held]
    assert creeping and max(creeping) <= CREEP_SPEED + 0.2
    passing = [hand_back for t, *_, hand_back in trace if wheel.events[0]["t"] < t < held]
    assert passing and not any(passing)   # no hand-back in the oncoming lane until held there
    assert trace[-1][1] == "E-A_1" and trace[-1][3] == 0.0 and trace[-1][4]   # stopped, and may hand back
    assert 0.0 < trace[-1][2] <= HOLD_MARGIN + 1.0    # short of the junction
    # the hand-back: the autopilot takes the car from the nearest place on its route
    assert after[0][0] == "A-E_1" and after[-1][2] == ("A-E", "E-D") and after[-1][1] > 1.0


def test_a_person_guided_back_into_their_lane_is_held_there(net):
    out = [(1.0, Controls(steer=-0.25, throttle=0.3)), (0.9, Controls(steer=0.25, throttle=0.3))]
    back = [(1.5, Controls(steer=0.5)), (1.5, Controls(steer=-0.5))]
    trace, _, wheel = drive_to_the_junction(net, [*out, (2.5, Controls(throttle=0.6)), *back,
                                                  (6.0, Controls(throttle=0.6))])
    kinds = [event["type"] for event in wheel.events]
    assert kinds == ["oncoming", "guide_back", "own_lane"], kinds
    assert trace[-1][1] == "A-E_1" and trace[-1][3] == 0.0 and trace[-1][4] and trace[-1][2] > HOLD_MARGIN


def test_a_takeover_in_sumos_own_overtaking_is_handed_back_driving_forward(net):
    """SUMO's autopilot overtakes a standing car through the oncoming lane; the person takes over
    there, passes it, steers back into their lane and hands back: SUMO drives on along the road
    (SUMO's oncoming-lane state, kept through every placement, drove the car backwards until what
    it had passed stopped it, and the episode stood there for good)."""
    from trustroute.harness.simulation.manual_measures import signed_offset
    from trustroute.harness.simulation.sumo_start import SumoConfig, fresh_session

    with fresh_session(net, 1, SumoConfig(step_length=0.05)) as sumo:
        sumo.route.add("planned", ["E-A"])
        sumo.vehicle.add("ego", "planned", departPos="10", departSpeed="13", departLane="1")
        sumo.vehicle.add("standing", "planned", departPos="200", departLane="1")
        sumo.vehicle.setSpeedMode("standing", 0)
        sumo.vehicle.setSpeed("standing", 0.0)
        shape = sumo.lane.getShape("E-A_1")
        lane_angle = math.degrees(math.atan2(shape[-1][0] - shape[0][0], shape[-1][1] - shape[0][1]))
        wheel, manual, handed_back, since = Wheel("ego"), False, None, 0
        for _ in range(1600):   # 80 s
            if not manual and handed_back is None and sumo.vehicle.getLaneID("ego").startswith("A-E"):
                manual = True   # taken over in the oncoming lane, SUMO overtaking
            pose = wheel.driving.pose if manual and wheel.driving else None
            if pose is not None:   # out past the standing car, then back into the own lane
                left = signed_offset(shape, pose.x, pose.y)
                fx, fy = math.sin(math.radians(pose.angle)), math.cos(math.radians(pose.angle))
                sx, sy = sumo.vehicle.getPosition("standing")
                ahead = (sx - pose.x) * fx + (sy - pose.y) * fy
                error = math.radians((pose.angle - lane_angle + 540) % 360 - 180)
                wanted = max(-0.25, min(0.25, 0.12 * (left - (3.0 if ahead > -10 else 0.0))))
                wheel.controls = Controls(steer=max(-0.3, min(0.3, 0.8 * (wanted - error))),
                                          throttle=0.5 if pose.speed < 6 else 0.0)
                if ahead < -12 and abs(left) < 0.5 and wheel.may_hand_back:
                    manual, handed_back = False, sumo.vehicle.getLanePosition("ego")
            wheel.step(sumo, manual, "E-A")
            sumo.simulationStep()
            since += handed_back is not None
            if since == 100:   # 5 s after the hand-back
                break
        assert handed_back is not None
        assert [event["type"] for event in wheel.events] == ["oncoming", "own_lane"]
        # the autopilot drove on along its lane, ahead of where it was handed back
        assert sumo.vehicle.getLaneID("ego") == "E-A_1"
        assert sumo.vehicle.getLanePosition("ego") > handed_back + 30.0
        assert sumo.vehicle.getSpeed("ego") > 5.0
