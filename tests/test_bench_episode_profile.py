"""The episode profile's timers: they count what runs inside them and leave no wrapper behind."""

from __future__ import annotations

from collections import defaultdict

import pytest

pytest.importorskip("libsumo")

from benchmarks import bench_episode_profile as profile  # noqa: E402
from trustroute.harness.simulation import episode  # noqa: E402


def test_the_timers_wrap_the_phases_and_put_the_originals_back_even_on_an_error():
    original = episode.SumoEpisode.__dict__["commit"]
    wall, cpu, counts = defaultdict(float), defaultdict(float), defaultdict(int)
    with pytest.raises(RuntimeError), profile._phase_timers(wall, cpu, counts):
        assert episode.SumoEpisode.__dict__["commit"] is not original
        with pytest.raises(AttributeError):
            episode.SumoEpisode.commit(None, None, 0.0, 0.0)   # the wrapper times the call, then re-raises
        raise RuntimeError("leave the block")
    assert episode.SumoEpisode.__dict__["commit"] is original
    assert counts["commit"] == 1 and wall["commit"] > 0 and cpu["commit"] >= 0


def test_per_episode_phases_add_up_to_the_total():
    seconds = {"run": 0.020, "sumo_steps": 0.004, "commit": 0.002, "inject": 0.001, "watch": 0.001,
               "insert_ego": 0.0005, "sumo_start": 0.006, "sumo_close": 0.001, "roads_table": 0.0005,
               "choose": 0.001}
    row = profile._per_episode(seconds, wall=0.040, episodes=2)
    # run less what runs inside it (SUMO, insert_ego, commit, watch, the tables), in ms / 2
    assert row["loop_python"] == pytest.approx(2.5)
    assert row["total"] == pytest.approx(20.0)
    assert row["other"] == pytest.approx(20.0 - (10.0 + 0.5))   # less run and choose
    bare = profile._per_episode({"sumo_start": 0.006, "sumo_steps": 0.001, "sumo_close": 0.001}, 0.010, 1)
    assert bare["other"] == pytest.approx(2.0) and "loop_python" not in bare
