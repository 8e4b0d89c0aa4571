"""The same defaults at every door: each packaged name and each default, run through the API and
through the CLI, gives the same answer (both read trustroute/core/defaults.py and trustroute/app)."""

from __future__ import annotations

import dataclasses
import inspect
import json

import pytest

import trustroute
from tests.cli import cli_json
from trustroute.app.planning import PlanSettings
from trustroute.app.runs import EpisodeSettings
from trustroute.app.synthesis import EvaluationSettings, SynthesisSettings
from trustroute.core import defaults
from trustroute.core.packaged import SPEC_TOWNS, SPECS
from trustroute.harness.cli import cli
from trustroute.networks.town import TOWNS
from trustroute.participants.driver_model import DRIVER_MODELS
from trustroute.participants.driver_population import POPULATIONS


def _option_default(command: str, name: str):
    """The default of a CLI option (by its Python name) of `trustroute COMMAND`."""
    group = cli
    for part in command.split():
        group = group.get_command(None, part)  # type: ignore[arg-type]
    return next(p.default for p in group.params if p.name == name)


# The API's calls take a settings object (`settings=`, None: the object's defaults) and its fields
# by keyword: the default of such a field is the settings object's.
API_SETTINGS = {trustroute.synthesize: SynthesisSettings, trustroute.evaluate: EvaluationSettings,
                trustroute.run_episode: EpisodeSettings}


def _api_default(function, name: str):
    parameters = inspect.signature(function).parameters
    if name in parameters:
        return parameters[name].default
    assert parameters["settings"].default is None
    return next(f.default for f in dataclasses.fields(API_SETTINGS[function]) if f.name == name)


@pytest.mark.parametrize(("command", "option", "function", "argument", "value"), [
    ("synth", "tau", trustroute.synthesize, "tau", defaults.TAU),
    ("synth", "time_limit", trustroute.synthesize, "time_limit", defaults.TIME_LIMIT),
    ("synth", "work_limit", trustroute.synthesize, "work_limit", defaults.WORK_LIMIT),
    ("synth", "horizon", trustroute.synthesize, "horizon", defaults.SYNTH_HORIZON),
    ("synth", "belief_rule", trustroute.synthesize, "belief_rule", defaults.BELIEF_RULE),
    ("synth", "objective", trustroute.synthesize, "objective", defaults.OBJECTIVE),
    ("evaluate", "fallback_after", trustroute.evaluate, "fallback_after", defaults.FALLBACK_AFTER),
    ("evaluate", "belief_rule", trustroute.evaluate, "belief_rule", defaults.BELIEF_RULE),
    ("run", "policy_name", trustroute.run_episode, "policy", defaults.POLICY),
    ("run", "seed", trustroute.run_episode, "seed", defaults.SEED),
    ("analyze", "belief_source", trustroute.analyze, "belief_source", defaults.BELIEF_SOURCE),
    # `trustroute plan` and its run in the application layer (trustroute/app/planning.py)
    ("plan", "sizes", PlanSettings, "sizes", defaults.PLAN_PARTICIPANTS),
    ("plan", "alpha", PlanSettings, "alpha", defaults.PLAN_ALPHA),
    ("plan", "target", PlanSettings, "target", defaults.PLAN_TARGET),
    ("plan", "seed", PlanSettings, "seed", defaults.PLAN_SEED),
    ("plan", "pilot_bootstrap", PlanSettings, "pilot_bootstrap", defaults.PILOT_BOOTSTRAP),
    ("plan", "simulations", PlanSettings, "simulations", None),
    ("plan", "pilot", PlanSettings, "pilot", None),
])
def test_every_door_declares_the_one_default(command, option, function, argument, value):
    assert _option_default(command, option) == _api_default(function, argument) == value


def test_the_api_and_the_cli_cap_episodes_alike():
    # the CLI's --max-junctions defaults to "the cap", the API's max_junctions names it
    assert _option_default("evaluate", "max_junctions") is None
    assert _api_default(trustroute.evaluate, "max_junctions") == defaults.JUNCTION_CAP
    assert _api_default(trustroute.run_episode, "engine") == defaults.EPISODE_ENGINE == "sumo"


def test_every_door_takes_the_same_number_of_background_vehicles():
    # `run --background`, the study key and the API's SumoConfig (run_episode's and a study's
    # episodes) accept 0 to the one maximum and refuse one more
    from trustroute.core.errors import InputError
    from trustroute.harness.simulation.sumo_start import SumoConfig
    from trustroute.harness.study.config import study_config_from_dict

    top = defaults.MAX_BACKGROUND_VEHICLES
    from trustroute.core.ranges import BACKGROUND_VEHICLES
    from trustroute.harness.commands.options import Checked

    option = next(p for p in cli.get_command(None, "run").params  # type: ignore[union-attr]
                  if p.name == "background_vehicles")
    assert isinstance(option.type, Checked) and option.type.accepted is BACKGROUND_VEHICLES
    assert (BACKGROUND_VEHICLES.kind.minimum, BACKGROUND_VEHICLES.kind.maximum) == (0, top)
    study = {"participants": 1, "seed": 1, "specs": ["phi1"], "conditions": ["free"]}
    for count in (0, top):
        config = study_config_from_dict({"study": {**study, "background_vehicles": count}})
        assert config.background_vehicles == count
        assert SumoConfig(background_vehicles=count).background_vehicles == count
    for count in (-1, top + 1):
        with pytest.raises(InputError, match=f"from 0 to {top}"):
            study_config_from_dict({"study": {**study, "background_vehicles": count}})
        with pytest.raises(InputError, match=f"background_vehicles: expected an integer from 0 to {top}"):
            SumoConfig(background_vehicles=count)


# their towns are built on first use (csomor from packaged plain XML, city from sumo-rl's data)
SLOW_SPECS = {"csomor5", "city5"}
SLOW_TOWNS = {"csomor", "city"}


@pytest.mark.parametrize("spec", [pytest.param(name, marks=pytest.mark.slow) if name in SLOW_SPECS else name
                                  for name in SPECS.names()])
def test_each_packaged_spec_evaluates_alike_through_the_api_and_the_cli(capsys, spec):
    """Defaults only: a packaged spec brings its town (city5, csomor5), the policy is "free", the
    fallback, cap and filter are the defaults."""
    api = trustroute.evaluate(spec)
    cli_value = cli_json(capsys, "evaluate", spec, defaults.POLICY)
    assert (cli_value["lower"], cli_value["upper"]) == (api.lower, api.upper)
    assert cli_value["fallback_after"] == defaults.FALLBACK_AFTER
    assert cli_value["max_junctions"] == defaults.JUNCTION_CAP
    assert cli_value["belief_rule"] == defaults.BELIEF_RULE


@pytest.mark.slow
def test_a_packaged_spec_knows_its_town():
    assert SPEC_TOWNS == {"city5": "city", "csomor5": "csomor"}
    assert trustroute.load_spec("city5").start in trustroute.load_town("city").states


@pytest.mark.parametrize("town", [pytest.param(name, marks=pytest.mark.slow) if name in SLOW_TOWNS else name
                                  for name in TOWNS.names()])
def test_each_packaged_town_loads_alike(capsys, town):
    summary = cli_json(capsys, "model", "--town", town)
    assert summary["town_hash"] == trustroute.load_town(town).content_hash[:12]


@pytest.mark.parametrize("driver", DRIVER_MODELS.names())
def test_each_packaged_driver_loads_alike_and_the_api_takes_its_name(capsys, driver):
    summary = cli_json(capsys, "model", "--driver", driver)
    assert summary["driver_hash"] == trustroute.load_driver_model(driver).content_hash[:12]
    # the API takes packaged names for town and driver wherever it takes objects
    api = trustroute.evaluate("phi1", town="town01_carla", driver=driver)
    cli_value = cli_json(capsys, "evaluate", "phi1", "free", "--town", "town01_carla", "--driver", driver)
    assert (cli_value["lower"], cli_value["upper"]) == (api.lower, api.upper)


@pytest.mark.parametrize("population", POPULATIONS.names())
def test_each_packaged_population_evaluates_alike(capsys, population):
    shown = cli_json(capsys, "population", "show", population)
    api = trustroute.evaluate("phi1", population=population)
    cli_value = cli_json(capsys, "evaluate", "phi1", "free", "--population", population)
    assert shown["types"] and (cli_value["lower"], cli_value["upper"]) == (api.lower, api.upper)


@pytest.mark.parametrize("spec", ["phi1", "phi1_trust"])   # the plain unfolding per type, the joint one
def test_a_population_evaluation_gives_each_type_alike_through_the_api_and_the_cli(capsys, spec):
    """Both doors take the per-type values from one evaluation (trustroute/app/synthesis.py,
    `evaluate_problem`): the API's `type_values` are the CLI's `population.type_values`; one driver
    model has none."""
    api = trustroute.evaluate(spec, population="driver_population_three_types")
    cli_value = cli_json(capsys, "evaluate", spec, "free", "--population", "driver_population_three_types")
    assert api.type_values is not None and [t.name for t in api.type_values] == ["builder", "flat", "wary"]
    assert len({t.lower for t in api.type_values}) == 3   # three different values, not one copied
    assert [t.to_dict() for t in api.type_values] == cli_value["population"]["type_values"]
    assert (cli_value["lower"], cli_value["upper"]) == (api.lower, api.upper)
    assert trustroute.evaluate(spec).type_values is None


def test_a_serialised_population_evaluation_keeps_each_type_s_value(capsys):
    """`to_dict()` of the API's evaluation, as JSON, holds the per-type values the CLI's --json
    gives under `population.type_values` (the CLI builds its JSON from that one dict); without a
    population it has no such key."""
    api = trustroute.evaluate("phi1", population="driver_population_three_types")
    cli_value = cli_json(capsys, "evaluate", "phi1", "free", "--population", "driver_population_three_types")
    serialised = json.loads(json.dumps(api.to_dict()))
    assert serialised["type_values"] == cli_value["population"]["type_values"]
    assert [t["name"] for t in serialised["type_values"]] == ["builder", "flat", "wary"]
    assert "type_values" not in cli_value and "type_values" not in trustroute.evaluate("phi1").to_dict()


@pytest.mark.slow
def test_one_episode_is_the_same_through_the_api_and_the_cli(capsys):
    api = trustroute.run_episode("phi2", seed=3)
    ran = cli_json(capsys, "run", "phi2", "--seed", "3")
    assert ran["route"] == api.roads["directed_road"].tolist()
    for key in ("episode_id", "satisfied", "junctions", "takeovers", "final_trust", "end_reason"):
        assert ran[key] == api.summary[key], key


@pytest.mark.slow
def test_a_synthesis_with_the_defaults_is_the_same_through_the_api_and_the_cli(capsys, tmp_path):
    api = trustroute.synthesize("phi1")
    made = cli_json(capsys, "synth", "phi1", "--out", str(tmp_path / "p.json"))
    assert (made["lower"], made["upper"], made["horizon"], made["tau"]) == (
        api.lower, api.upper, defaults.SYNTH_HORIZON, defaults.TAU)


def test_a_work_limited_synthesis_is_the_same_through_the_api_and_the_cli(capsys, tmp_path):
    """A work limit stops both doors after the same work: the same bounds, whatever the clock."""
    api = trustroute.synthesize("phi1", horizon=10, work_limit=20_000)
    made = cli_json(capsys, "synth", "phi1", "--horizon", "10", "--work-limit", "20000",
                    "--out", str(tmp_path / "p.json"))
    assert (made["lower"], made["upper"], made["stopped_by"]) == (api.lower, api.upper, api.stopped_by)
    assert api.stopped_by == "work limit"


@pytest.mark.slow
def test_the_analysis_of_a_study_uses_one_default_belief_source(capsys, tmp_path):
    config = tmp_path / "study.toml"
    config.write_text('[study]\nparticipants = 2\nseed = 5\nengine = "model"\nspecs = ["phi1"]\n'
                      'conditions = ["free"]\n')
    study = tmp_path / "study"
    trustroute.run_study(config, study)
    api = trustroute.analyze(study)
    cli_value = cli_json(capsys, "analyze", str(study), "--no-report")
    assert cli_value["belief_source"] == api.belief_source
    assert cli_value["cells"] == api.to_dict()["cells"]
