"""Frames between SUMO steps: at wall-clock pace a step (0.5 s) alone gives two frames a second;
the worker fills the time between steps with dead-reckoned frames, marked as predicted."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from trustroute.harness.live.view import dead_reckoned
from trustroute.harness.live.worker import LiveOptions, RemoteDriver
from trustroute.harness.study.context import study_context
from trustroute.harness.study.plan import plan_episodes
from trustroute.harness.study.runner import run_planned_episode

from .conftest import tiny_config
from .test_live_worker import live_episode


def frame(**changes) -> dict:
    base = {"type": "frame", "t": 10.0, "x": 100.0, "y": 50.0, "angle": 90.0, "speed": 10.0,
            "road": "A-B", "lane": "A-B_0", "mode": "auto", "junction": "B",
            "vehicles": [[120.0, 50.0, 0.0, "traffic", 5.0], [90.0, 50.0, 180.0, "obstacle", 0.0]],
            "persons": [[110.0, 55.0, "pedestrian"]]}
    return {**base, **changes}


def test_a_dead_reckoned_frame_moves_every_vehicle_along_its_heading():
    moved = dead_reckoned(frame(), 0.2)
    assert moved["predicted"] is True and moved["t"] == pytest.approx(10.2)
    assert (moved["x"], moved["y"]) == pytest.approx((102.0, 50.0))          # east at 10 m/s
    assert moved["vehicles"][0][:2] == pytest.approx([120.0, 51.0])         # north at 5 m/s
    assert moved["vehicles"][1][:2] == pytest.approx([90.0, 50.0])          # the obstacle stands
    assert moved["persons"] == frame()["persons"]
    assert {k: v for k, v in moved.items() if k not in ("t", "x", "y", "vehicles", "predicted")} == \
        {k: v for k, v in frame().items() if k not in ("t", "x", "y", "vehicles")}


class FakeTime:
    """The wall clock and the pipe: polling for controls lets the wall clock run on; `controls`
    are (wall time, control) delivered once the clock reaches their time."""

    def __init__(self, controls=()) -> None:
        self.now, self.sent, self.controls = 0.0, [], list(controls)

    def __call__(self) -> float:
        return self.now

    def send(self, message: dict) -> None:
        self.sent.append({**message, "wall": self.now})

    def poll(self, timeout: float = 0.0) -> bool:
        if self.controls and self.controls[0][0] <= self.now + timeout:
            self.now = max(self.now, self.controls[0][0])
            return True
        self.now += timeout
        return False

    def recv(self) -> dict:
        return self.controls.pop(0)[1]


NO_TRAFFIC = SimpleNamespace(   # SUMO with the ego alone (what the frames read of it)
    vehicle=SimpleNamespace(getIDList=lambda: [], getTypeID=lambda _: "car", getSignals=lambda _: 0,
                            getRoute=lambda _: ("A-B", "B-C"), getRouteIndex=lambda _: 0),
    vehicletype=SimpleNamespace(getLength=lambda _: 5.0, getWidth=lambda _: 1.8, getHeight=lambda _: 1.5,
                                getShapeClass=lambda _: "passenger"),
    person=SimpleNamespace(getIDList=lambda: []))


def ego_at(time: float) -> SimpleNamespace:
    return SimpleNamespace(time=time, x=0.0, y=5.0 * time, angle=0.0, speed=5.0, lane="A-B_0",
                           road="A-B", lane_position=5.0 * time)


@pytest.mark.parametrize("frame_rate", [25.0, 40.0])
def test_at_wall_clock_pace_frames_come_at_the_frame_rate_and_never_run_ahead(frame_rate):
    clock = FakeTime()
    driver = RemoteDriver(clock, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1.0, frame_rate=frame_rate),
                          clock=clock)
    for step in range(9):   # 4 s of simulated time at 0.5 s a step, observed at wall-clock pace
        driver.observe(NO_TRAFFIC, ego_at(0.5 * step), "auto", "A-B")
    frames = [m for m in clock.sent if m["type"] == "frame"]
    walls = [m["wall"] for m in frames]
    rate = (len(frames) - 1) / (walls[-1] - walls[0])
    assert rate >= 0.9 * frame_rate and rate <= 1.05 * frame_rate
    assert max(b - a for a, b in zip(walls, walls[1:], strict=False)) <= 1.0 / frame_rate + 1e-9
    stepped = [m for m in frames if not m.get("predicted")]
    assert [m["t"] for m in stepped] == [0.5 * step for step in range(9)]   # every step is shown
    for message in frames:   # a predicted frame is where the ego is at its time, never past the next step
        assert message["y"] == pytest.approx(5.0 * message["t"], abs=0.01)   # positions in cm
        assert message["t"] <= 0.5 * math.floor(message["t"] / 0.5) + 0.5
        assert message["t"] <= message["wall"] + 1e-9   # the simulation's pace: never ahead of the wall


def test_no_frames_are_predicted_while_paused_and_they_go_on_from_the_resume():
    clock = FakeTime(controls=[(0.2, {"type": "pause"}), (2.0, {"type": "resume"})])
    driver = RemoteDriver(clock, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1.0), clock=clock)
    driver.observe(NO_TRAFFIC, ego_at(0.0), "auto", "A-B")
    driver.observe(NO_TRAFFIC, ego_at(0.5), "auto", "A-B")
    frames = [m for m in clock.sent if m["type"] == "frame"]
    assert [m["wall"] for m in frames if 0.2 < m["wall"] < 2.0] == []       # paused: nothing moves
    after = [m for m in frames if m["wall"] >= 2.0]
    assert len(after) >= 7 and after[-1]["t"] == 0.5 and not after[-1].get("predicted")
    for message in after:   # the simulated time goes on from where the pause held it
        assert message["t"] == pytest.approx(min(0.2 + (message["wall"] - 2.0), 0.5))


def test_a_takeover_does_not_wait_for_the_pace_and_the_frames_go_on_without_a_gap():
    clock = FakeTime(controls=[(1.2, {"type": "takeover"})])
    driver = RemoteDriver(clock, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1.0), clock=clock)
    for step in range(9):
        driver.observe(NO_TRAFFIC, ego_at(0.5 * step), "auto", "A-B")   # (the episode switches the mode)
    frames = [m for m in clock.sent if m["type"] == "frame"]
    walls = [m["wall"] for m in frames]
    assert max(b - a for a, b in zip(walls, walls[1:], strict=False)) <= driver.frame_interval + 1e-9
    hurried = next(m for m in frames if m["wall"] >= 1.2 and not m.get("predicted"))
    assert hurried["wall"] == pytest.approx(1.2) and hurried["t"] == 1.5   # shown at once, not at 1.5 s
    assert frames[-1]["t"] == 4.0 and frames[-1]["wall"] == pytest.approx(4.0 - 0.3)   # 0.3 s gained


class HandingBack(FakeTime):
    """A station that hands back when warned of the road's end."""

    def send(self, message: dict) -> None:
        super().send(message)
        if message["type"] == "warning":
            self.controls.append((self.now, {"type": "hand_back"}))


def test_a_takeover_carried_to_the_next_road_does_not_wait_for_the_pace_either(tmp_path):
    """A takeover read in the step before a road's commit point is taken by the episode in the
    closing step and applied at the step after it (the next road's): that step is not paced either,
    so the mode change follows the takeover by no wall time (the clock is the test's, moved only by
    the worker's waits), not by a step (0.5 s at pace 1)."""
    *_, quiet, _ = live_episode(tmp_path, [])
    before_closing = next(m["t"] for m in quiet.sent if m["type"] == "road" and m["index"] == 1)
    config = tiny_config(tmp_path, participants=1)
    task = plan_episodes(config)[0]
    clock = HandingBack()
    driver = RemoteDriver(clock, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1.0, client="scripted"),
                          clock=clock, episode_id=task.episode_id)
    sent_at = []

    def observe(sumo, ego, mode, road):
        if ego.time == before_closing:   # read now, so the episode takes it in the closing step
            sent_at.append(clock.now)
            clock.controls.append((clock.now, {"type": "takeover"}))
        driver.observe(sumo, ego, mode, road)

    record = run_planned_episode(study_context(config), task, driver=driver, observer=observe, person=driver)
    assert bool(record.roads["takeover"].iloc[2])   # carried to the next road
    manual = next(m for m in clock.sent if m["type"] == "mode" and m["mode"] == "manual")
    assert manual["t"] == pytest.approx(before_closing + 1.0)   # applied two steps on ...
    assert manual["wall"] - sent_at[0] < driver.frame_interval   # ... without waiting for either
