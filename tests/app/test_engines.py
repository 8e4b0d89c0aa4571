"""The engine registry: each engine declares what it can do, and the doors that take an engine
name accept exactly the registry's."""

from __future__ import annotations

import pytest

import trustroute
from trustroute.app.engines import ENGINES, SIMULATED, engine_named
from trustroute.core.errors import InputError
from trustroute.harness.simulation import gym_env
from trustroute.harness.study import config as study_config


def test_each_engine_declares_its_capabilities():
    capabilities = {name: (e.drives_sumo, e.synthetic, e.records) for name, e in ENGINES.items()}
    assert capabilities == {"sumo": (True, True, True), "model": (False, True, False),
                            "live": (True, False, False)}
    assert SIMULATED == ("sumo", "model")


def test_the_doors_accept_the_registry_engines():
    assert set(study_config.ENGINES) == set(ENGINES)
    assert gym_env.ENGINES == SIMULATED


def test_an_unknown_or_unsimulated_engine_is_refused():
    with pytest.raises(InputError, match="use one of sumo, model"):
        engine_named("live", simulated=True)
    with pytest.raises(InputError, match="unknown engine 'carla'"):
        engine_named("carla")
    with pytest.raises(InputError, match="engine: unknown engine 'live' \\(fix: use one of sumo, model\\)"):
        trustroute.run_episode("phi1", engine="live")
    with pytest.raises(InputError, match="rrd: a Rerun recording needs the SUMO engine"):
        trustroute.run_episode("phi1", engine="model", rrd="x.rrd")
