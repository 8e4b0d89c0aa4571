"""Episodes share one simulation per process (sumo_start.sumo_session): the simulation kept open is
returned to its empty state, and an episode's tables are the same, bit for bit, as in a fresh SUMO.

This rests on no SUMO random draw reaching an episode; the first test checks that directly by
running every episode with two SUMO seeds.
"""

from __future__ import annotations

import multiprocessing
import os
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from trustroute.harness.simulation import sumo_start
from trustroute.harness.simulation.episode import EpisodeOptions, run_episode
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.sumo_start import SumoConfig, close_simulation, reusable
from trustroute.harness.study.config import study_config_from_dict
from trustroute.harness.study.plan import EpisodeTask, plan_episodes
from trustroute.harness.study.runner import run_planned_episode, validate_study
from trustroute.networks.sumo_net import build_net
from trustroute.networks.town import load_town
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.free import trust_free_policy


@pytest.fixture(scope="module")
def study():
    """Six participants, phi1 and phi2, trust-free and trust-aware: 24 episodes that meet every
    incident kind (pedestrians early and late, obstacles with and without an oncoming vehicle,
    trucks with parked cars)."""
    config = study_config_from_dict({"study": {
        "name": "reuse", "participants": 6, "seed": 11, "engine": "sumo", "specs": ["phi1", "phi2"],
        "conditions": ["free", "aware"]}}, "test_sumo_reuse", Path.cwd())
    return validate_study(config), plan_episodes(config)   # the study's context, built once


def _tables(context, task: EpisodeTask) -> dict[str, pa.Table]:
    return run_planned_episode(context, task).tables()


def _differing(a: dict[str, pa.Table], b: dict[str, pa.Table]) -> list[str]:
    """The names of the tables that differ."""
    return [name for name in a if not a[name].equals(b[name])]


@pytest.fixture
def starts(monkeypatch) -> list[list[str]]:
    """Every libsumo start's command line, in order."""
    import libsumo

    started: list[list[str]] = []
    original = libsumo.start

    def start(command, *args, **kwargs):
        started.append(list(command))
        return original(command, *args, **kwargs)

    monkeypatch.setattr(libsumo, "start", start)
    return started


def test_no_sumo_random_draw_reaches_an_episode(study, monkeypatch):
    context, tasks = study
    kinds = set()
    original = sumo_start.sumo_command
    for task in tasks:
        close_simulation()
        first = _tables(context, task)
        close_simulation()
        monkeypatch.setattr(sumo_start, "sumo_command",
                            lambda net, seed, options: original(net, seed + 7919, options))
        other = _tables(context, task)
        monkeypatch.setattr(sumo_start, "sumo_command", original)
        assert _differing(first, other) == [], task.episode_id
        kinds |= set(first["incidents"].column("incident").to_pylist())
        scenes = first["incidents"].column("scene").to_pylist()
        kinds |= {"oncoming" for scene in scenes if scene and "oncoming=inc" in scene}
        kinds |= {"late" for scene in scenes if scene and "timing=late" in scene}
    assert kinds >= {"pedestrian", "obstacle", "truck", "oncoming"}


def test_episodes_in_one_simulation_equal_fresh_ones(study, starts):
    context, tasks = study
    close_simulation()
    reused = [_tables(context, task) for task in tasks]
    assert len(starts) == 1   # one start, then every episode returned the simulation to its snapshot
    for task, tables in zip(reversed(tasks), reversed(reused), strict=True):
        close_simulation()
        assert _differing(_tables(context, task), tables) == [], task.episode_id
    assert len(starts) == 1 + len(tasks)


def test_another_command_line_starts_afresh_and_the_seed_alone_does_not(study, starts):
    context, tasks = study
    close_simulation()
    _tables(context, tasks[0])
    _tables(context, tasks[1])   # another seed: the same simulation
    assert len(starts) == 1
    assert starts[0][starts[0].index("--seed") + 1] == str(tasks[0].seed)
    coarse = replace(SumoConfig(), step_length=0.25)
    run_planned_episode(context, tasks[0], sumo_config=coarse)
    assert len(starts) == 2 and starts[1][starts[1].index("--step-length") + 1] == "0.25"


def test_an_episode_that_raises_closes_the_simulation(study, starts):
    context, tasks = study
    close_simulation()
    expected = _tables(context, tasks[2])

    def observer(sumo, ego, mode, road):
        if ego.time > 20.0:
            raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        run_planned_episode(context, tasks[1], observer=observer)
    assert sumo_start._open == []   # what the episode left behind went with the simulation
    assert _differing(_tables(context, tasks[2]), expected) == []
    assert len(starts) == 2   # the failed episode ran in the first simulation; the next starts afresh


def test_runs_whose_sumo_draws_matter_or_that_write_outputs_start_afresh(tmp_path):
    assert reusable(SumoConfig())
    assert not reusable(SumoConfig(background_vehicles=3))
    assert not reusable(SumoConfig(route_files=("trips.rou.xml",)))
    assert not reusable(SumoConfig(output_dir=str(tmp_path)))
    assert not reusable(SumoConfig(gui=True))


def _child_episode(context, task: EpisodeTask, connection) -> None:
    tables = run_planned_episode(context, task, sumo_config=replace(SumoConfig(), step_length=0.25)).tables()
    connection.send(len(tables["roads"]))


def test_a_forked_worker_leaves_the_parents_simulation_alone(study, starts):
    context, tasks = study
    close_simulation()
    expected = _tables(context, tasks[3])
    snapshot = sumo_start._open[0].snapshot
    fork = multiprocessing.get_context("fork")
    parent, child = fork.Pipe()
    process = fork.Process(target=_child_episode, args=(context, tasks[3], child))
    process.start()
    assert parent.recv() > 0
    process.join(60)
    assert process.exitcode == 0
    assert snapshot.is_file()   # the child's own simulation and exit did not touch the parent's
    assert _differing(_tables(context, tasks[3]), expected) == []
    assert len(starts) == 1


def test_a_net_rewritten_in_place_starts_afresh(starts, tmp_path, driver):
    town = load_town()
    spec = load_spec("phi1", town)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec)
    net = tmp_path / "town.net.xml"
    shutil.copyfile(build_net(town).path, net)

    def episode() -> None:
        run_episode(setup, trust_free_policy(town, spec), SyntheticDriver(driver, np.random.default_rng(1)),
                    "rewritten", 1, EpisodeOptions(net_path=net))

    close_simulation()
    episode()
    episode()
    assert len(starts) == 1
    later = net.stat().st_mtime_ns + 10**9
    net.write_bytes(net.read_bytes())   # the same net written again, as a re-import would
    os.utime(net, ns=(later, later))
    episode()
    assert len(starts) == 2
