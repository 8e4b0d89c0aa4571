"""The API's errors name its keyword arguments, never the CLI's flags, and its seeds and names
follow the CLI's rules."""

from __future__ import annotations

from pathlib import Path

import pytest

import trustroute
from trustroute.app.runs import EpisodeSettings
from trustroute.core.errors import InputError
from trustroute.harness.simulation.sumo_start import SumoConfig

STUDY = {"study": {"participants": 1, "seed": 1, "engine": "model", "specs": ["phi1"],
                   "conditions": ["free"]}}
POPULATION = "driver_population_three_types"


@pytest.mark.parametrize(("call", "named"), [
    (lambda: trustroute.load_town("nope"), "as town or a packaged town name"),
    (lambda: trustroute.synthesize("phi1", horizon=-1),
     "horizon: expected an integer from 1 to 1000, got -1"),
    (lambda: trustroute.run_episode("phi1", settings=EpisodeSettings(engine="model", initial_trust=0)),
     "initial_trust: 0 is not a trust level"),
    (lambda: trustroute.run_episode("phi1", engine="model", initial_trust=0),
     "initial_trust: 0 is not a trust level"),
    (lambda: trustroute.run_episode("phi1", engine="model", sumo=SumoConfig()),
     "sumo: a SUMO configuration needs the SUMO engine, not 'model'"),
    (lambda: trustroute.run_episode("phi1", engine="model", observer=print),
     "observer: an observer of SUMO's steps needs the SUMO engine, not 'model'"),
    (lambda: trustroute.run_episode("phi1", settings=EpisodeSettings(engine="model", net=Path("x.net.xml"))),
     "net: a SUMO net needs the SUMO engine, not 'model'"),
    (lambda: EpisodeSettings(engine="model", rrd=Path("x.rrd")),
     "rrd: a Rerun recording needs the SUMO engine"),
    (lambda: EpisodeSettings(engine="carla"), "engine: unknown engine 'carla'"),
])
def test_api_errors_name_keyword_arguments(call, named):
    with pytest.raises(InputError, match=named) as caught:
        call()
    assert "--" not in str(caught.value)


def test_a_command_in_an_api_error_keeps_its_flags(tmp_path):
    spec = tmp_path / "street.toml"
    spec.write_text('name = "street"\nstart = "E-A"\nformula = "F v"\n\n[states]\n'
                    'v = { street = "Rudower Chaussee" }\n')
    with pytest.raises(InputError, match=r"\(trustroute town roads TOWN --street NAME\)"):
        trustroute.load_spec(spec)


def test_analyze_names_its_belief_source_argument(tmp_path):
    study = trustroute.run_study(STUDY, out=tmp_path / "study").study_dir
    with pytest.raises(InputError, match="belief_source: unknown belief source 'bogus'") as caught:
        trustroute.analyze(study, belief_source="bogus")
    assert "--" not in str(caught.value)


@pytest.mark.parametrize("seed", [-1, 2**31, 1.5, "3"])
def test_an_episode_seed_follows_the_cli_rule(seed):
    with pytest.raises(InputError, match=rf"seed: expected an integer from 0 to 2147483647, got {seed!r}"):
        trustroute.run_episode("phi1", engine="model", seed=seed)


def test_the_largest_seed_and_a_numpy_seed_run():
    import numpy as np

    assert trustroute.run_episode("phi1", engine="model", seed=2**31 - 1).summary["junctions"] > 0
    assert trustroute.run_episode("phi1", engine="model", seed=np.int64(3)).summary["junctions"] > 0


@pytest.mark.parametrize(("call", "what"), [(lambda: trustroute.load_town(""), "town"),
                                            (lambda: trustroute.load_spec(""), "spec"),
                                            (lambda: trustroute.load_driver_model(""), "driver model")])
def test_an_empty_name_is_said_to_be_empty(call, what):
    with pytest.raises(InputError, match=f"the {what} name is empty"):
        call()


# Each rule the CLI checks of these settings holds at the API's door too, as the same InputError
# (the CLI's message with its flags said as keywords), never a bare ValueError or a silent run.
@pytest.mark.parametrize(("call", "named"), [
    (lambda: trustroute.synthesize("phi1", horizon=20, time_limit=0),
     r"time_limit: 0.0 is not a number in \(0, "),   # the CLI's words: --time-limit 0 is 0.0
    (lambda: trustroute.synthesize("phi1", horizon=20, time_limit=float("nan")),
     "time_limit: nan is not a finite number"),
    (lambda: trustroute.evaluate("phi1", "free", max_junctions=-1),
     "max_junctions: expected an integer from 0 to 10000, got -1"),
    (lambda: trustroute.evaluate("phi1", "free", fallback_after=-1),
     "fallback_after: expected an integer from 0 to 10000, got -1"),
    (lambda: trustroute.evaluate("phi1", "free", max_nodes=0), "max_nodes: expected an integer >= 1, got 0"),
    (lambda: trustroute.evaluate("phi1_trust", "free", time_limit=-1),
     r"time_limit: -1.0 is not a number in \(0, "),
    (lambda: trustroute.evaluate("phi1", "free", time_limit=1.0),
     "time_limit: applies to specs with trust-state atoms only"),
    (lambda: trustroute.evaluate("phi1", "free", population=POPULATION, max_nodes=5),
     "max_nodes: the pruning limits are not used for a driver population"),
    (lambda: trustroute.evaluate("phi1", "free", driver="driver_model", population=POPULATION),
     "population: a driver model and a driver population were both given"),
    (lambda: trustroute.synthesize("phi1", horizon=20, belief_rule="authors"),
     "belief_rule: unknown belief rule 'authors'"),
    (lambda: trustroute.evaluate("phi1", "free", belief_rule="authors"),
     "belief_rule: unknown belief rule 'authors'"),
    (lambda: trustroute.synthesize("phi1", horizon=5, objective="robust"),
     "objective: objective robust needs the types to weigh"),
    (lambda: trustroute.synthesize("phi1", horizon=5, objective="bogus"),
     "objective: unknown objective 'bogus'"),
    (lambda: trustroute.synthesize("phi1", horizon=5, population=POPULATION, clusters="on"),
     "clusters: cluster policies apply to a single driver model"),
    (lambda: trustroute.run_episode("phi1", engine="bogus"), "engine: unknown engine 'bogus'"),
    (lambda: trustroute.run_episode("phi1", engine="model", rrd="x.rrd"),
     "rrd: a Rerun recording needs the SUMO engine"),
    (lambda: trustroute.run_episode("phi1", engine="model", net="town.net.xml"),
     "net: a SUMO net needs the SUMO engine, not 'model'"),
    (lambda: trustroute.run_study(STUDY, out="unused", workers=0), "workers: expected an integer from 1"),
])
def test_api_settings_follow_the_cli_rules(call, named):
    with pytest.raises(InputError, match=named) as caught:
        call()
    assert "--" not in str(caught.value)


def test_a_limit_evaluate_refuses_is_refused_before_a_policy_is_synthesized(tmp_path):
    # trustroute/app/synthesis.py, `evaluate_problem`: the limits first, then the policy ("aware"
    # would be synthesized and cached in `cache_dir`)
    with pytest.raises(InputError, match="^time_limit: applies to specs with trust-state atoms only"):
        trustroute.evaluate("phi1", "aware", cache_dir=tmp_path / "cache", time_limit=1.0)
    assert not (tmp_path / "cache").exists()


def test_a_command_quoted_in_an_api_error_keeps_its_flags(tmp_path):
    # "run `trustroute study CONFIG --out DIR` first" is a command to type: its --out stays
    with pytest.raises(InputError, match="`trustroute study CONFIG --out DIR`"):
        trustroute.analyze(tmp_path)


def test_an_episode_jammed_by_background_traffic_is_bad_input_and_a_stuck_ego_a_bug():
    from trustroute.harness.simulation.background import SimTimeCapReached, TrafficJam
    from trustroute.harness.simulation.sumo_start import SumoConfig

    # Town01 with 200 background vehicles locks up on seed 0 within 300 s of sim time
    with pytest.raises(TrafficJam, match="the 200 background vehicles jammed the town's roads") as caught:
        trustroute.run_episode("phi1", seed=0,
                               sumo=SumoConfig(background_vehicles=200, max_sim_seconds=300.0))
    assert isinstance(caught.value, InputError) and isinstance(caught.value, SimTimeCapReached)
    # without background traffic an episode still running at its cap is not the input's fault: the
    # error keeps its type and traceback (here the cap is shorter than any drive)
    with pytest.raises(SimTimeCapReached, match="still running after 20 s of sim time") as caught:
        trustroute.run_episode("phi1", seed=0, sumo=SumoConfig(max_sim_seconds=20.0))
    assert not isinstance(caught.value, InputError)


# An argument of the wrong type is bad input like a bad value: an InputError naming the argument
# and what it takes, never a TypeError or AttributeError from deep inside.
@pytest.mark.parametrize(("call", "named"), [
    (lambda: trustroute.load_spec(3), "spec: expected a Spec, a file path or a packaged name, got 3"),
    (lambda: trustroute.run_episode(3, engine="model"), "spec: expected a Spec"),
    (lambda: trustroute.load_town(3.5), "town: expected a Town, a file path or a packaged name, got 3.5"),
    (lambda: trustroute.evaluate("phi1", "free", town=["pentagon"]), "town: expected a Town"),
    (lambda: trustroute.load_driver_model(1), "driver: expected a DriverModel"),
    (lambda: trustroute.synthesize("phi1", driver={"trust": 1}, horizon=2), "driver: expected a DriverModel"),
    (lambda: trustroute.evaluate("phi1", "free", population=3), "population: expected a DriverPopulation"),
    (lambda: trustroute.run_episode("phi1", 5, engine="model"),
     "policy: expected a policy name .*, a policy file, a SynthesisResult or a RoutingPolicy, got 5"),
    (lambda: trustroute.run_study(42, out="unused"),
     "config: expected a study config file, a dict or a StudyConfig, got 42"),
])
def test_an_argument_of_the_wrong_type_is_named(call, named):
    with pytest.raises(InputError, match=named) as caught:
        call()
    assert "--" not in str(caught.value)


def test_the_api_writes_nothing_into_a_package(tmp_path):
    """A package (its config and tables folder) is published read-only at the API's doors as at the
    CLI's: a policy file or a policy cache in one is refused naming the keyword, and nothing is
    written there."""
    package = tmp_path / "package"
    (package / "tables").mkdir(parents=True)
    (package / "study_config.json").write_text("{}")
    with pytest.raises(InputError, match="out: the policy file lies in the package"):
        trustroute.synthesize("phi1", horizon=4, out=package / "policy.json")
    with pytest.raises(InputError, match="cache_dir: the policy cache lies in the package"):
        trustroute.evaluate("phi1", "aware", cache_dir=package / "cache")
    assert sorted(p.name for p in package.rglob("*")) == ["study_config.json", "tables"]


def test_the_api_refuses_a_policy_file_it_cannot_write_before_any_work(tmp_path, monkeypatch):
    """`synthesize(out=...)` checks its policy file as `trustroute synth --out` does, before the
    problem is compiled or anything synthesized: in a package, one of the files it reads (the
    spec), a directory; for one driver model and for a population alike."""
    import trustroute.app.synthesis as synthesis_module

    def no_work(*args, **kwargs):
        raise AssertionError("work began before the policy file was checked")

    monkeypatch.setattr(trustroute, "_compiled", no_work)
    monkeypatch.setattr(synthesis_module, "synthesize_problem", no_work)
    monkeypatch.setattr(synthesis_module, "synthesize_for_population", no_work)
    package = tmp_path / "package"
    (package / "tables").mkdir(parents=True)
    (package / "study_config.json").write_text("{}")
    spec = tmp_path / "route.toml"
    spec.write_text((Path(trustroute.__file__).parent / "core" / "specs" / "phi1.toml").read_text())
    for population in (None, POPULATION):
        with pytest.raises(InputError, match="out: the policy file lies in the package"):
            trustroute.synthesize("phi1", horizon=4, population=population, out=package / "policy.json")
        with pytest.raises(InputError, match="out: the policy file would overwrite spec"):
            trustroute.synthesize(spec, horizon=4, population=population, out=spec)
        with pytest.raises(InputError, match="out: the policy file path is a directory"):
            trustroute.synthesize("phi1", horizon=4, population=population, out=tmp_path)
    assert sorted(p.name for p in package.rglob("*")) == ["study_config.json", "tables"]


def test_the_api_checks_the_report_folder_before_reading_the_study(tmp_path):
    """`analyze(out=...)` checks the folder its report goes to as `trustroute analyze --out` does,
    before the study is read (one rule, trustroute/app/analysis.py `report_wanted`)."""
    taken = tmp_path / "report"
    taken.write_text("a file")
    with pytest.raises(InputError, match="out: the report folder exists and is not a directory"):
        trustroute.analyze(tmp_path / "no-study", out=taken)
