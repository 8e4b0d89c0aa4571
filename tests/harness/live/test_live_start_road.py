"""A person's takeover on the start road acts in the step the episode reads it, as on any other
road (harness/simulation/episode.py, `SumoEpisode.person_control`). The start road has no
observation of its own, so the takeover counts for the first road after it
(harness/simulation/takeover_decision.py, `count_for_first_road`)."""

from __future__ import annotations

import pytest

from trustroute.harness.live.worker import LiveOptions, RemoteDriver, sumo_config
from trustroute.harness.study.context import study_context
from trustroute.harness.study.plan import plan_episodes
from trustroute.harness.study.runner import run_planned_episode

from .conftest import tiny_config
from .test_live_worker import Pipe, live_episode


def _taken_over_at(tmp_path, read_at: float, options: LiveOptions | None = None):
    """The episode with the person's takeover read in the step of `read_at` (handed back when warned,
    in assisted driving): its record and the driver (`driver.connection.sent`: the messages the
    station was sent)."""
    config = tiny_config(tmp_path, participants=1)
    task = plan_episodes(config)[0]
    pipe = Pipe([], hand_back_when_warned=options is None)
    options = options or LiveOptions(pace=1e6, client="scripted")
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5, options, episode_id=task.episode_id)

    def observe(sumo, ego, mode, road):
        if ego.time == read_at:
            pipe.controls.append({"type": "takeover"})
        driver.observe(sumo, ego, mode, road)

    record = run_planned_episode(study_context(config), task, driver=driver, observer=observe, person=driver,
                                 sumo_config=sumo_config(options))
    return record, driver


@pytest.mark.parametrize("road", [0, 1], ids=["start road", "first road"])
def test_a_takeover_on_the_start_road_acts_in_the_next_step_as_on_any_road(road, tmp_path):
    """Read in a step of the start road (its first) or of the first road (its second), the
    takeover acts in the next step, the one that reads the person's controls: the ego drives it in
    manual and the station is told so then. Either way it is the first road's takeover."""
    *_, quiet = live_episode(tmp_path, [])
    times, lanes = quiet.kinematics["time"].tolist(), quiet.kinematics["lane"].tolist()
    name = quiet.roads["directed_road"].iloc[road]
    read_at = [t for t, lane in zip(times, lanes, strict=True) if lane.rsplit("_", 1)[0] == name][road]
    record, driver = _taken_over_at(tmp_path, read_at)
    sent = driver.connection.sent
    applied = times[times.index(read_at) + 1]
    modes = dict(zip(record.kinematics["time"], record.kinematics["mode"], strict=True))
    assert (modes[read_at], modes[applied]) == ("auto", "manual")
    assert next(m["t"] for m in sent if m["type"] == "mode") == applied
    roads = record.roads.set_index("index")
    assert roads["takeover"].isna()[0] and bool(roads.loc[1, "takeover"])   # the start road: no observation
    incidents = record.incidents.set_index("index")
    assert bool(incidents.loc[1, "takeover"]) and incidents.loc[1, "takeover_start"] == applied
    end = incidents.loc[1, "takeover_end"]   # handed back when warned, before the first road's end
    assert applied < end <= roads.loc[2, "sim_time_in"]


def test_by_wheel_a_takeover_on_the_start_road_too_close_to_stop_is_handed_back_at_its_commit_point(
        tmp_path):
    """By wheel, the ego inserted 40 m before the start road's commit point at the road's speed: a
    takeover read at 1 s acts in the next step, the hold brakes, and, the car too close to stop short
    of the commit point, the episode hands back there, as on any road. It is the first road's
    takeover, from the next step to that commit point."""
    options = LiveOptions(pace=1e6, driving="continuous")
    record, driver = _taken_over_at(tmp_path, 1.0, options)
    times = record.kinematics["time"].tolist()
    applied = times[times.index(1.0) + 1]
    modes = [(m["mode"], m["t"]) for m in driver.connection.sent if m["type"] == "mode"]
    assert [mode for mode, _ in modes[:2]] == ["manual", "auto"] and modes[0][1] == applied
    assert [e["type"] for e in driver.wheel.events] == ["hold"]
    assert [e["type"] for e in driver.events] == ["takeover"]   # the person never handed back
    roads = record.roads.set_index("index")
    start_road = roads.loc[0, "directed_road"]
    commit = modes[1][1]
    lanes = dict(zip(record.kinematics["time"], record.kinematics["lane"], strict=True))
    assert lanes[commit].rsplit("_", 1)[0] == start_road   # handed back still on the start road
    incidents = record.incidents.set_index("index")
    assert (incidents.loc[1, "takeover_start"], incidents.loc[1, "takeover_end"]) == (applied, commit)
    assert record.summary["end_reason"] == "accepted"
