"""The study's context: what every episode of a study shares, built from the config alone.

Town, nominal driver model, specs, episode setups, the policies of every (spec, condition) and the
participants' driver models. `study_context` builds it; whoever runs the study builds it once and
hands it down: the runner (harness/study/runner.py: `validate_study` builds it before any worker,
the workers forked after that inherit it, and the expected values and the consolidation are given
it), the live study (harness/live/server.py, and each live episode's process), replay, planning
and the benchmarks.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from trustroute.app.inputs import Inputs, driver_of, population_of, spec_of, town_of
from trustroute.app.policy import PolicySettings, policy_for
from trustroute.app.problem import compile_problem
from trustroute.core.errors import InputError
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.plan import participant_models, participant_types
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.belief.driver_types import lift_population
from trustroute.policies.belief.problem import Problem
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, checked_belief_rule
from trustroute.policies.routing.protocol import RoutingPolicy


@dataclass(frozen=True, eq=False)
class StudyContext:
    """What every episode of a study shares; built from the config alone."""

    config: StudyConfig
    town: Town
    nominal: DriverModel  # the AV's model (its belief filter) and the default driver
    specs: dict[str, Spec]
    setups: dict[str, EpisodeSetup]
    policies: dict[tuple[str, str], RoutingPolicy]  # (spec name, condition label) -> policy
    participants: list[DriverModel] | None  # per-participant driver models; None: all nominal
    participant_types: list[str] | None = None  # per-participant true type ([drivers] population)
    # (spec name, condition label) -> setup, where a condition's AV filters with another model than
    # the nominal one ("robust": the type-aware model of its population, docs/driver_types.md)
    condition_setups: dict[tuple[str, str], EpisodeSetup] = field(default_factory=dict)

    def driver_model(self, participant: int) -> DriverModel:
        return self.nominal if self.participants is None else self.participants[participant]

    def setup(self, spec_name: str, condition: str) -> EpisodeSetup:
        """The episode setup of a (spec, condition) cell."""
        return self.condition_setups.get((spec_name, condition), self.setups[spec_name])

    @functools.cached_property
    def reference_filter(self) -> DriverModel:
        """The "reference" belief source's one filter for this study (`reference_model`), made
        once: the "robust" condition's AV model itself when the study has that condition, so that
        a judge can tell the AV's own filter by identity (harness/study/planning.py, `is_own_verdict`)."""
        robust = next((setup.driver_model for setup in self.condition_setups.values()), None)
        return reference_model(self.config.to_dict(), self.nominal, robust)


def reference_model(config: Mapping[str, object], nominal: DriverModel,
                    robust: DriverModel | None = None) -> DriverModel:
    """The one filter of the "reference" belief source, the same for every condition
    (analysis/belief_sources.py): the type-aware model of the study's population, the "robust"
    condition's (`robust`: that model when the caller holds it lifted already) else the [drivers]';
    the study's driver model `nominal` when there is neither or its file is gone. `config`: the
    study's settings by key (StudyConfig.to_dict(), a manifest's "config")."""
    robust_path = config.get("robust_population")
    path = robust_path or config.get("driver_population")
    if not path or not Path(str(path)).is_file():
        return nominal
    if robust is not None and path == robust_path:
        return robust
    return lift_population(population_of(str(path)))


def belief_rule(config: StudyConfig) -> BeliefRule:
    """The AV's filter of the study (a name `load_study_config` has checked)."""
    return checked_belief_rule(config.belief_rule)


def aware_policy_path(town: Town, driver: DriverModel, spec: Spec, config: StudyConfig) -> Path:
    """Where the "aware" policy of this study is cached (the resolver's entry for its horizon and filter)."""
    from trustroute.policies.resolve import aware_cache_path

    return aware_cache_path(town, driver, spec, config.policy_cache, aware_horizon(config),
                            belief_rule(config))


def aware_horizon(config: StudyConfig) -> int:
    """The synthesis horizon of "aware": the config's, else the resolver's default (20 junctions)."""
    from trustroute.policies.resolve import AWARE_HORIZON

    return AWARE_HORIZON if config.horizon is None else config.horizon


def policy_settings(config: StudyConfig, progress: bool = False) -> PolicySettings:
    """How the study's named conditions find or make their policies (trustroute/app/policy.py)."""
    return PolicySettings(cache_dir=config.policy_cache, horizon=aware_horizon(config),
                          belief_rule=belief_rule(config), progress=progress)


def resolve_condition_policy(
    condition: str, town: Town, driver: DriverModel, spec: Spec, config: StudyConfig, progress: bool = False
) -> RoutingPolicy:
    """A condition ("free", "aware": synthesized and cached if missing, or a policy file) as a policy."""
    return policy_for(compile_problem(Inputs(town=town, spec=spec, driver=driver)), condition,
                      policy_settings(config, progress))


def robust_problem(town: Town, spec: Spec, config: StudyConfig) -> Problem:
    """The compiled problem of the "robust" condition: `config.robust_population` lifted, with the
    type-aware model and lifted spec its AV uses."""
    source = config.robust_population
    if source is None:  # load_study_config refuses such a config
        raise InputError(config.source_path, "study.robust_population", "the 'robust' condition needs the "
                         "driver population its policy is made for",
                         'add robust_population = "types.json" to [study] (docs/driver_types.md)')
    return compile_problem(Inputs(town=town, spec=spec, population=population_of(source),
                                  population_source=str(source)))


def robust_condition_policy(town: Town, spec: Spec, config: StudyConfig,
                            progress: bool = False) -> tuple[RoutingPolicy, DriverModel, Spec]:
    """The "robust" condition: the policy of `config.robust_objective` for `config.robust_population`
    (synthesized and cached if missing), with the type-aware model and lifted spec its AV uses."""
    problem = robust_problem(town, spec, config)
    policy = policy_for(problem, config.robust_objective, policy_settings(config, progress))
    return policy, problem.driver, problem.spec


def load_study_inputs(town_path: str | Path | None, driver_path: str | Path | None,
                      spec_paths) -> tuple[Town, DriverModel, dict[str, Spec]]:
    """(town, nominal driver model, {spec name: Spec}) of a study: every spec checked against the
    town and the driver model's trust levels. The study's context and the analysis of a study
    directory (analysis/study_directory.py) load them here."""
    town = town_of(town_path)
    nominal = driver_of(driver_path)
    specs = {Path(path).stem: spec_of(path, town, nominal) for path in spec_paths}
    return town, nominal, specs


def study_context(config: StudyConfig, progress: bool = False) -> StudyContext:
    """Build the study's context from the config alone (`progress`: bars while policies are
    synthesized, in the main process). Each call builds a new one: the caller holds it and passes
    it to what needs it (workers forked after it is built inherit it and load no policy again)."""
    town, nominal, specs = load_study_inputs(config.town, config.driver_model, config.specs)
    setups = {
        name: EpisodeSetup(
            town=town,
            driver_model=nominal,
            spec=spec,
            junction_cap=config.junction_cap,
            fallback_after=config.fallback_after,
            report_every=config.report_every,
            belief_rule=belief_rule(config),
        )
        for name, spec in specs.items()
    }
    policies = {}
    condition_setups = {}
    for name, spec in specs.items():
        for condition, label in zip(config.conditions, config.condition_names, strict=True):
            if condition == "robust":
                policy, model, lifted_spec = robust_condition_policy(town, spec, config, progress)
                condition_setups[(name, label)] = replace(setups[name], driver_model=model,
                                                          spec=lifted_spec)
                policies[(name, label)] = policy
            else:
                policies[(name, label)] = resolve_condition_policy(condition, town, nominal, spec,
                                                                   config, progress)
    return StudyContext(
        config=config,
        town=town,
        nominal=nominal,
        specs=specs,
        setups=setups,
        policies=policies,
        participants=participant_models(config, nominal),
        condition_setups=condition_setups,
        participant_types=participant_types(config),
    )
