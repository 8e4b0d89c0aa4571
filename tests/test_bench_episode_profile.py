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


def test_libsumo_functions_are_listed_by_the_episodes_cpu_and_the_rest_summed():
    def side(cpu: dict[str, float], counts: dict[str, int]) -> dict:
        return {"native_cpu": cpu, "native_counts": counts}

    totals = {"episode": side({"simulation_step": 0.010, "vehicle_add": 0.004, "lane_getLength": 0.001,
                               "person_add": 0.002}, {"simulation_step": 20, "vehicle_add": 8,
                                                      "lane_getLength": 4, "person_add": 2}),
              "bare_open": side({"simulation_step": 0.006, "route_add": 0.001},
                                {"simulation_step": 18, "route_add": 2})}
    rows = profile.by_function(totals, episodes=2, shown=2)
    assert list(rows) == ["simulation_step", "vehicle_add", "others"]
    assert rows["simulation_step"] == {"episode": [5.0, 10.0], "bare_open": [3.0, 9.0]}
    assert rows["vehicle_add"]["bare_open"] == [0.0, 0.0]
    # person_add, lane_getLength and the bare loop's route_add: summed, nothing lost
    assert rows["others"] == {"episode": [1.5, 3.0], "bare_open": [0.5, 1.0]}
    assert "| others | 1.500 | 3 | 0.500 | 1 |" in profile.functions_table({"libsumo_by_function_cpu": rows})


def test_sumo_alone_is_bounded_below_by_taking_the_cheapest_call_off_every_call():
    totals = {"episode": {"native_cpu": {"simulation_step": 0.010, "simulation_getTime": 0.0004,
                                         "vehicle_add": 0.004},
                          "native_counts": {"simulation_step": 200, "simulation_getTime": 200,
                                            "vehicle_add": 8}}}
    ratio = profile.sumo_alone_ratio(totals, bare_open_ms=5.0, episodes=2)
    # 7.2 ms and 204 calls per episode; the cheapest call with >= 10 a run: getTime, 2 µs
    assert ratio["timed"] == pytest.approx(7.2 / 5.0)
    assert ratio["cheapest_call_ms"] == pytest.approx(0.002)
    assert ratio["lower"] == pytest.approx((7.2 - 204 * 0.002) / 5.0, abs=5e-4)   # to 3 decimals
