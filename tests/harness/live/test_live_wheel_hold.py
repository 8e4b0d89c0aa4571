"""The hold of a person driving by wheel reaches the station in every frame (`held`), as the
episode's one rule has it (harness/simulation/wheel_driving.py `Wheel.held`): the live worker's
`RemoteDriver` by wheel on the Town01 net, towards the end of A-E (the episode's open road), SUMO
stepping 0.1 s. Each case is checked against the rule as docs/live_studies.md states it in terms of
the warnings the station is sent (held after `hold`; after `guide_back` once back in the lane or
after a collision; after `held_off_lane` or `stopped_off_road`; never guided back, never before the
hold, never on autopilot), and against what the car does: held, the accelerator held down moves it
no faster."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from trustroute.harness.live.protocol import Frame
from trustroute.harness.live.worker import LiveOptions, RemoteDriver
from trustroute.harness.simulation.driving_style import AUTOPILOT, MANUAL
from trustroute.harness.simulation.vehicle_model import Controls

from ..simulation.test_wheel_driving import net, park_truck  # noqa: F401  (net: the Town01 net, a fixture)
from .test_live_frames import FakeTime

STEP = 0.1
# into the oncoming lane
OUT = [(1.0, Controls(steer=-0.25, throttle=0.3)), (0.9, Controls(steer=0.25, throttle=0.3))]
# a warning's news of the lane: off it, or back on it
OFF_LANE = {"oncoming": True, "off_road": True, "own_lane": False, "on_road": False}


def drive_live(net, program, start: float = 418.0, parked: float | None = None) -> list[dict]:  # noqa: F811
    """What the worker sends while `program` ((seconds, Controls or None: on autopilot), ...) drives
    the ego from `start` metres into A-E; `parked`: a truck standing in the oncoming lane (E-A) that
    far into it."""
    from trustroute.harness.simulation.sumo_start import SumoConfig, fresh_session

    clock = FakeTime()
    driver = RemoteDriver(clock, (1, 2, 3, 4, 5, 6, 7), 4, LiveOptions(driving="continuous"), clock=clock)
    with fresh_session(net, 1, SumoConfig(step_length=STEP)) as sumo:
        sumo.route.add("planned", ["A-E", "E-D"])
        sumo.vehicle.add("ego", "planned", departPos=str(start), departSpeed="8", departLane="1")
        if parked is not None:
            park_truck(sumo, parked)
        sumo.simulationStep()
        for seconds, controls in program:
            for _ in range(round(seconds / STEP)):
                x, y = sumo.vehicle.getPosition("ego")
                ego = SimpleNamespace(time=sumo.simulation.getTime(), x=x, y=y,
                                      angle=sumo.vehicle.getAngle("ego"), speed=sumo.vehicle.getSpeed("ego"),
                                      lane=sumo.vehicle.getLaneID("ego"))
                driver.observe(sumo, ego, AUTOPILOT.name if controls is None else MANUAL.name, "A-E")
                if controls is not None:   # (a takeover starts from released controls)
                    driver.apply({"type": "control", "source": "wheel", "steer": controls.steer,
                                  "throttle": controls.throttle, "brake": controls.brake})
                sumo.simulationStep()
    return clock.sent


def held_by_the_warnings(sent: list[dict]) -> list[bool]:
    """For each stepped frame, whether the car is held as the documented rule reads it from the
    warnings and modes sent before it."""
    begun = off_lane = collided = stopped = False
    held = []
    for message in sent:
        kind = message.get("kind")
        if message["type"] == "mode":   # every change of mode ends the hold
            begun = off_lane = collided = stopped = False
        elif message["type"] == "warning":
            begun |= kind in ("hold", "guide_back")
            collided |= kind == "collision"
            stopped |= kind in ("held_off_lane", "stopped_off_road")
            off_lane = OFF_LANE.get(kind, off_lane)
        elif message["type"] == "frame" and not message.get("predicted"):
            held.append(stopped or (begun and (not off_lane or collided)))
    return held


def check(sent: list[dict], warnings: list[str]) -> list[dict]:
    """The stepped frames, each checked: a frame of the protocol, its `held` the rule's, a
    predicted frame's its step's; held, the car no faster from one frame to the next, though the
    accelerator is held down. `warnings`: the driving events the case must bring."""
    assert [m["kind"] for m in sent if m["type"] == "warning"] == warnings
    frames = [m for m in sent if m["type"] == "frame"]
    for frame in frames:   # (the fake pipe marks each message with its wall time)
        Frame.model_validate({key: value for key, value in frame.items() if key != "wall"})
    stepped = [m for m in frames if not m.get("predicted")]
    assert [frame["held"] for frame in stepped] == held_by_the_warnings(sent)
    shown = None
    for frame in frames:
        if frame.get("predicted"):
            assert frame["held"] == shown["held"]
        else:
            shown = frame
    for before, after in zip(stepped, stepped[1:], strict=False):
        if before["held"] and after["held"] and before["mode"] == after["mode"] == MANUAL.name:
            assert after["speed"] <= before["speed"] + 1e-9
    return stepped


def test_held_in_the_lane_from_the_hold_until_the_hand_back(net):  # noqa: F811
    sent = drive_live(net, [(12.0, Controls(throttle=0.5)), (2.0, None)])
    stepped = check(sent, ["hold"])
    manual = [frame["held"] for frame in stepped if frame["mode"] == MANUAL.name]
    assert not manual[0] and manual[-1] and manual == sorted(manual)   # not held, then held to the end
    assert not any(frame["held"] for frame in stepped if frame["mode"] == AUTOPILOT.name)
    standing = [frame for frame in stepped if frame["held"] and frame["speed"] == 0.0]
    assert len(standing) > 20   # standing held, the accelerator held down, for seconds


def test_guided_back_the_pedals_are_the_persons_until_stopped_short_of_the_junction(net):  # noqa: F811
    sent = drive_live(net, [*OUT, (22.0, Controls(throttle=0.6))])
    stepped = check(sent, ["oncoming", "guide_back", "held_off_lane"])
    assert not all(frame["held"] for frame in stepped) and stepped[-1]["held"]


def test_guided_back_into_the_lane_the_car_is_held_there(net):  # noqa: F811
    back = [(1.5, Controls(steer=0.5)), (1.5, Controls(steer=-0.5))]
    sent = drive_live(net, [*OUT, (2.5, Controls(throttle=0.6)), *back, (6.0, Controls(throttle=0.6))])
    stepped = check(sent, ["oncoming", "guide_back", "own_lane"])
    assert stepped[-1]["held"] and stepped[-1]["speed"] == 0.0


def test_guided_back_and_collided_the_car_is_held_where_it_stands(net):  # noqa: F811
    sent = drive_live(net, [*OUT, (22.0, Controls(throttle=0.6))], parked=40.0)
    stepped = check(sent, ["oncoming", "guide_back", "collision"])
    assert stepped[-1]["held"] and stepped[-1]["speed"] == 0.0


def test_stopped_off_the_road_the_car_is_held_where_it_stands(net):  # noqa: F811
    off = [(1.5, Controls(steer=0.3, throttle=0.3)), (6.0, Controls(throttle=0.5))]   # right, off the road
    sent = drive_live(net, off, start=10.0)
    stepped = check(sent, ["off_road", "stopped_off_road"])
    assert not stepped[0]["held"] and stepped[-1]["held"] and stepped[-1]["speed"] == 0.0


@pytest.mark.parametrize(("program", "parked", "warnings"), [
    ([(4.0, Controls(throttle=0.5))], None, []),                                         # in its lane
    ([*OUT, (3.0, Controls(throttle=0.3))], None, ["oncoming"]),                          # passing
    ([*OUT, (3.0, Controls(throttle=0.3))], 470.0, ["oncoming", "collision"]),            # a crash
])
def test_far_from_the_junction_the_car_is_never_held(net, program, parked, warnings):  # noqa: F811
    sent = drive_live(net, program, start=10.0, parked=parked)
    assert not any(frame["held"] for frame in check(sent, warnings))
