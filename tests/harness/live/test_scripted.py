"""In lockstep the scripted participant keeps within the server's flood limit, and a refused
answer fails at once instead of leaving the episode waiting; outside lockstep it answers at once,
but its trust reports still keep within that limit."""

from __future__ import annotations

import pytest

from trustroute.harness.live.protocol import TokenBucket, error_reply
from trustroute.harness.live.scripted import (
    CLIENT_BURST,
    CLIENT_RATE,
    LockstepRefused,
    ScriptedParticipant,
)

from .conftest import tiny_config


class FakeClock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        assert seconds > 0.0
        self.now += seconds


def test_a_burst_of_answers_is_spread_so_the_server_refuses_none(tmp_path):
    clock = FakeClock()
    player = ScriptedParticipant(tiny_config(tmp_path), 0, lockstep=True,
                                 bucket=TokenBucket(burst=CLIENT_BURST, rate=CLIENT_RATE, clock=clock),
                                 sleep=clock.sleep)
    server = TokenBucket(clock=clock)
    answers = 0
    for _ in range(200):   # every message at the same instant, as a fast episode sends them
        for _reply in player.respond({"type": "warning", "kind": "hand_back", "distance": 90.0, "t": 1.0}):
            assert server.take(), f"the server refused answer {answers + 1}"
            answers += 1
    assert answers == 200
    assert clock.now == pytest.approx((200 - CLIENT_BURST) / CLIENT_RATE)   # it waited, and no longer


def test_without_the_client_limit_the_same_burst_is_refused(tmp_path):
    clock = FakeClock()
    server = TokenBucket(clock=clock)
    assert not all(server.take() for _ in range(200))   # what the pacing above prevents


def test_a_refused_lockstep_answer_is_raised(tmp_path):
    player = ScriptedParticipant(tiny_config(tmp_path), 0, lockstep=True)
    with pytest.raises(LockstepRefused, match="rate_limited"):
        player.respond(error_reply("rate_limited", "too many messages; slow down"))
    relaxed = ScriptedParticipant(tiny_config(tmp_path), 0)
    assert relaxed.respond(error_reply("rate_limited", "too many messages; slow down")) == []
    assert relaxed.errors[0]["code"] == "rate_limited"


def test_outside_lockstep_answers_go_at_once(tmp_path):
    clock = FakeClock()
    player = ScriptedParticipant(tiny_config(tmp_path), 0,
                                 bucket=TokenBucket(burst=CLIENT_BURST, rate=CLIENT_RATE, clock=clock),
                                 sleep=clock.sleep)
    for _ in range(50):
        assert player.respond({"type": "warning", "kind": "hand_back", "distance": 90.0, "t": 1.0})
    assert clock.now == 0.0   # the episode drives on meanwhile: a late answer would miss its road


def test_outside_lockstep_reports_keep_within_the_limit_so_the_server_refuses_none(tmp_path):
    # a whole trial's prompts within an instant, as a live station at pace 1000 sends them: the
    # last road's answer, which the trial's end waits for, would otherwise be refused as a flood
    clock = FakeClock()
    player = ScriptedParticipant(tiny_config(tmp_path), 0,
                                 bucket=TokenBucket(burst=CLIENT_BURST, rate=CLIENT_RATE, clock=clock),
                                 sleep=clock.sleep)
    player.driver = player.new_driver(player.tasks[1])
    server = TokenBucket(clock=clock)
    roads = 60
    for index in range(1, roads + 1):
        prompt = {"episode_id": "e", "road": index}
        replies = player.respond({"type": "road", "index": index, "incident": "none", "takeover": False,
                                  "performance": "succ", "t": float(index), "prompt": prompt})
        assert [(reply["type"], reply["prompt"]) for reply in replies] == [("trust", prompt)]
        assert server.take(), f"the server refused report {index}"
    assert clock.now == pytest.approx((roads - CLIENT_BURST) / CLIENT_RATE)   # it waited, and no longer
    waited = clock.now
    for _ in range(50):   # the bucket is empty, and the other answers still go at once
        assert player.respond({"type": "warning", "kind": "hand_back", "distance": 90.0, "t": 1.0})
    assert clock.now == waited


def by_hand_frame(speed: float, t: float) -> dict:
    """A frame of the ego heading north on road A-B in its own lane, an obstacle 20 m ahead."""
    return {"type": "frame", "t": t, "x": 0.0, "y": 0.0, "angle": 0.0, "speed": speed, "road": "A-B",
            "lane": "A-B_0", "mode": "manual", "vehicles": [[0.0, 20.0, 0.0, "obstacle"]], "persons": []}


def test_by_hand_a_pull_out_not_begun_when_the_ego_stands_for_the_hand_back_is_given_up(tmp_path):
    # A slow answer (a loaded machine, a fast pace) can let the hand-back warning come before the
    # pull-out has begun; the ego then stands short of the junction for the hand-back while the
    # person waited for the pass, and the episode waited until the server closed the silent socket.
    player = ScriptedParticipant(tiny_config(tmp_path, specs=("phi2",)), 0, by_hand=True)
    assert player.respond({"type": "road", "road": "A-B", "t": 0.0}) == [{"type": "takeover"}]
    pressed = player.respond({"type": "mode", "mode": "manual", "t": 0.1})
    assert pressed == [{"type": "drive", "pedal": "accelerate"}]
    assert {"type": "steer", "lane": "oncoming"} in player.respond(by_hand_frame(5.0, 0.2))
    assert player.respond({"type": "warning", "kind": "hand_back", "distance": 40.0, "t": 0.3}) == []
    assert player.respond(by_hand_frame(2.0, 0.4)) == []   # still moving: the pull-out may begin
    assert player.respond(by_hand_frame(0.0, 0.5)) == [{"type": "hand_back"}]
    assert not player.passing and player.passes == 0


def test_by_hand_a_pull_out_waits_for_its_gap_before_the_warning(tmp_path):
    player = ScriptedParticipant(tiny_config(tmp_path, specs=("phi2",)), 0, by_hand=True)
    player.respond({"type": "road", "road": "A-B", "t": 0.0})
    player.respond({"type": "mode", "mode": "manual", "t": 0.1})
    player.respond(by_hand_frame(5.0, 0.2))
    assert player.respond(by_hand_frame(0.0, 0.3)) == []   # behind the obstacle, waiting to pull out
    assert player.passing


def oncoming_frame(t: float, obstacle_y: float) -> dict:
    """A frame of the ego on road A-B in the oncoming lane (B-A's), the obstacle at `obstacle_y`."""
    return {**by_hand_frame(8.0, t), "lane": "B-A_0", "vehicles": [[0.0, obstacle_y, 0.0, "obstacle"]]}


def test_by_hand_a_pass_the_autopilot_began_is_the_persons_once_in_control(tmp_path):
    # the takeover lands during the autopilot's pull-out, the obstacle already beside the ego: the
    # person finishes the pass and hands back once back in the own lane, and counts it
    player = ScriptedParticipant(tiny_config(tmp_path, specs=("phi2",)), 0, by_hand=True)
    player.respond({"type": "road", "road": "A-B", "t": 0.0})
    player.respond({"type": "mode", "mode": "manual", "t": 0.1})
    assert player.respond(oncoming_frame(0.2, -5.0)) == [{"type": "drive", "pedal": "release"}]
    assert player.respond({**by_hand_frame(8.0, 0.3), "vehicles": []}) == [{"type": "hand_back"}]
    assert player.passes == 1 and not player.passing


def test_by_hand_a_pass_whose_return_no_frame_showed_counts_when_the_road_ends(tmp_path):
    player = ScriptedParticipant(tiny_config(tmp_path, specs=("phi2",)), 0, by_hand=True)
    player.respond({"type": "road", "road": "A-B", "t": 0.0})
    player.respond({"type": "mode", "mode": "manual", "t": 0.1})
    assert {"type": "steer", "lane": "oncoming"} in player.respond(by_hand_frame(5.0, 0.2))
    player.respond(oncoming_frame(0.3, 10.0))
    assert player.passes == 0
    player.respond({"type": "road", "road": "B-C", "t": 0.4})   # no frame back in the own lane came
    assert player.passes == 1 and not player.passing
