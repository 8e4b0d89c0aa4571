"""trustroute: a study harness on SUMO for trust-aware routing of an autonomous vehicle.

The Python API is the few calls a researcher scripts with (README.md, "Python API"):

    load_town, load_driver_model, load_spec    read and validate the input files
    synthesize                                 a trust-aware policy with bounds L <= Pr_max <= U
    evaluate                                   the exact value of any policy
    run_episode                                one episode (SUMO, or the model engine)
    run_study                                  a simulated within-subject study
    analyze                                    the tables and statistics of a study

Every argument that names a town or a driver model may be omitted: the packaged town and driver
model of the paper are used. `import trustroute` is cheap: each call imports what it needs.

Subpackages: networks (towns and SUMO nets), participants (driver models), policies (scLDTL,
the trust POMDP, synthesis, routing policies), harness (episodes, studies, the CLI, the gymnasium
environment), analysis (satisfaction, statistics, reports, fitting). docs/README.md indexes the
documentation of the model and the file formats.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from trustroute.analysis.study.analysis import StudyAnalysis
    from trustroute.harness.simulation.episode import EpisodeRecord
    from trustroute.harness.study.config import StudyConfig
    from trustroute.harness.study.runner import StudyRun
    from trustroute.networks.town import Town
    from trustroute.participants.driver_model import DriverModel
    from trustroute.participants.driver_population import DriverPopulation
    from trustroute.policies.evaluation.plain import Evaluation
    from trustroute.policies.logic.spec import Spec
    from trustroute.policies.model.trust_pomdp import BeliefRule
    from trustroute.policies.routing.protocol import RoutingPolicy
    from trustroute.policies.synthesis.population import Objective, PopulationSynthesis
    from trustroute.policies.synthesis.result import SynthesisResult
    from trustroute.policies.synthesis.settings import SynthesisSettings

    # a policy argument: "free", "aware", a policy file, a SynthesisResult or any RoutingPolicy
    PolicyLike = str | Path | SynthesisResult | RoutingPolicy

__all__ = [
    "analyze",
    "evaluate",
    "load_driver_model",
    "load_spec",
    "load_town",
    "run_episode",
    "run_study",
    "synthesize",
]

PathLike = str | Path


def load_town(path: PathLike | None = None) -> Town:
    """The validated town of a town file (docs/formats/town.md); the packaged town when omitted."""
    from trustroute.networks.town import load_town as load

    return load(path)


def load_driver_model(path: PathLike | None = None) -> DriverModel:
    """The validated driver model of a file (docs/formats/driver_model.md); the packaged one when
    omitted."""
    from trustroute.participants.driver_model import load_driver_model as load

    return load(path)


def load_spec(spec: PathLike, town: Town | None = None) -> Spec:
    """The validated scLDTL spec of a spec file (docs/formats/spec.md), checked against `town`
    (default: the packaged town).

    `spec` is a file path or the name of a packaged spec ("phi1", "phi2", "phi1_strict",
    "phi2_strict", "phi1_trust"); an existing file of that name wins (trustroute/core/packaged.py,
    as for towns, driver models and populations).
    """
    from trustroute.policies.logic.spec import load_spec as load

    return load(spec, town if town is not None else load_town())


def _problem(spec: Spec | PathLike, town: Town | None,
             driver: DriverModel | None) -> tuple[Town, DriverModel, Spec]:
    """(town, driver model, spec) with the packaged defaults filled in."""
    from trustroute.policies.logic.spec import Spec

    town = town if town is not None else load_town()
    driver = driver if driver is not None else load_driver_model()
    spec = spec if isinstance(spec, Spec) else load_spec(spec, town)
    return town, driver, spec


def synthesize(spec: Spec | PathLike, town: Town | None = None, driver: DriverModel | None = None, *,
               horizon: int | None = None, tau: float = 1e-3, time_limit: float = 60.0,
               belief_rule: BeliefRule = "bayes", out: PathLike | None = None,
               population: DriverPopulation | PathLike | None = None,
               objective: Objective = "bayes") -> SynthesisResult | PopulationSynthesis:
    """A trust-aware policy for `spec` with certified bounds `result.lower <= Pr_max <= result.upper`.

    horizon: at most this many junctions (None: unbounded). tau: stop when upper - lower <= tau.
    time_limit: seconds (about). belief_rule: the AV's filter, exact "bayes" or the authors'
    "paper" update (docs/model.md). out: also write the policy file there
    (docs/formats/policy_file.md). `result.policy` is the policy; `result.lower` is its exact value.

    population: a driver population (object or file; instead of `driver`): synthesis for its mixture
    of driver types under `objective` ("bayes": the prior-weighted value, "robust": the worst
    type's; docs/driver_types.md), for any spec, trust-state atoms included. It returns a
    PopulationSynthesis: `lower <= optimum <= upper` of the objective, `type_values` the returned
    policy's value per type, `result` its SynthesisResult (`result.policy` the policy).
    """
    from trustroute.policies.model.trust_pomdp import build_pomdp
    from trustroute.policies.routing.files import save_policy
    from trustroute.policies.synthesis.settings import SynthesisSettings
    from trustroute.policies.synthesize_spec import synthesize_spec as search

    settings = SynthesisSettings(tau=tau, time_limit=time_limit, horizon=horizon, belief_rule=belief_rule)
    if population is not None:
        if driver is not None:
            raise ValueError("give driver or population, not both")
        return _synthesize_population(spec, town, population, objective, settings, out)
    town, driver, spec = _problem(spec, town, driver)
    result = search(build_pomdp(town, driver), spec, settings)
    if out is not None:
        save_policy(result, out, town, driver, spec)
    return result


def _synthesize_population(spec: Spec | PathLike, town: Town | None, population: DriverPopulation | PathLike,
                           objective: Objective, settings: SynthesisSettings,
                           out: PathLike | None) -> PopulationSynthesis:
    """`synthesize` for a driver population (the one synthesis entry decides the method)."""
    from trustroute.participants.driver_population import DriverPopulation, load_driver_population
    from trustroute.policies.logic.spec import Spec
    from trustroute.policies.routing.files import save_policy
    from trustroute.policies.synthesis.population import document_entries, policy_name
    from trustroute.policies.synthesize_spec import synthesize_for_population

    town = town if town is not None else load_town()
    if not isinstance(population, DriverPopulation):
        population = load_driver_population(population)
    if not isinstance(spec, Spec):
        spec = load_spec(spec, town)
    found = synthesize_for_population(town, population, spec, objective, settings,
                                      population_source=population.source_path)
    if out is not None:
        save_policy(found.result, out, town, found.pomdp.driver, found.spec,
                    population=document_entries(found), name=policy_name(found))
    return found


def _policy(policy: PolicyLike, town: Town, driver: DriverModel, spec: Spec,
            cache_dir: PathLike | None) -> RoutingPolicy:
    """A RoutingPolicy from "free", "aware", a policy file path, a SynthesisResult or a policy."""
    from trustroute.policies.resolve import resolve_policy
    from trustroute.policies.synthesis.result import SynthesisResult

    if isinstance(policy, str | Path):
        return resolve_policy(str(policy), town, driver, spec, cache_dir)
    if isinstance(policy, SynthesisResult):
        return policy.policy
    return policy


def evaluate(spec: Spec | PathLike, policy: PolicyLike = "free", town: Town | None = None,
             driver: DriverModel | None = None, *, fallback_after: int | None = 20,
             max_junctions: int = 60, belief_rule: BeliefRule = "bayes",
             cache_dir: PathLike | None = None) -> Evaluation:
    """The exact probability that `policy` satisfies `spec`, its expected final trust and how
    episodes end (no sampling; `value.lower`/`value.upper` certify it).

    policy: "free" (the trust-free shortest route), "aware" (synthesized for 20 junctions and
    cached in `cache_dir`), a policy file, a SynthesisResult or any RoutingPolicy.
    fallback_after: the study's rule, the shortest completion after that many junctions (None:
    the policy as given). max_junctions: the episode cap (docs/model.md, "Episodes").
    """
    from trustroute.policies.evaluation.settings import EvaluationSettings
    from trustroute.policies.evaluation.trust_state import evaluate_joint as exact
    from trustroute.policies.model.trust_pomdp import build_pomdp

    town, driver, spec = _problem(spec, town, driver)
    routing = _policy(policy, town, driver, spec, cache_dir)
    return exact(build_pomdp(town, driver), spec, routing,
                 EvaluationSettings(fallback_after=fallback_after, max_junctions=max_junctions,
                                    belief_rule=belief_rule))


def run_episode(spec: Spec | PathLike, policy: PolicyLike = "free", town: Town | None = None,
                driver: DriverModel | None = None, *, seed: int = 0, engine: str = "sumo",
                initial_trust: int | None = None, rrd: PathLike | None = None,
                cache_dir: PathLike | None = None) -> EpisodeRecord:
    """One episode of `spec` with `policy` and a synthetic driver drawn from `driver`.

    engine: "sumo" (libsumo: incidents, takeovers and performance measured in the simulation) or
    "model" (the trust POMDP alone, no SUMO). seed: SUMO's seed and the driver's Generator seed.
    initial_trust: the driver's initial trust (default: drawn from the model). rrd: also write a
    Rerun recording (SUMO engine only). policy: as for `evaluate`. Returns the logs:
    `record.summary` (dict), `record.roads`, `record.kinematics`, `record.incidents` (DataFrames,
    docs/dataset.md); the episode follows the study's rules (20-junction fallback, 60-junction cap).
    """
    import numpy as np

    from trustroute.core.errors import InputError
    from trustroute.harness.simulation.episode_tracker import EpisodeSetup
    from trustroute.participants.synthetic_driver import SyntheticDriver

    if engine not in ("sumo", "model"):
        raise ValueError(f"unknown engine {engine!r}; use 'sumo' or 'model'")
    if engine == "model" and rrd is not None:
        raise ValueError("a Rerun recording needs the SUMO engine (engine='sumo')")
    town, driver, spec = _problem(spec, town, driver)
    if initial_trust is not None and initial_trust not in driver.trust_levels:
        raise InputError("initial_trust", "", f"{initial_trust} is not a trust level of the model",
                         f"pass one of {list(driver.trust_levels)}")
    routing = _policy(policy, town, driver, spec, cache_dir)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec)
    synthetic = SyntheticDriver(driver, np.random.default_rng(seed), initial_trust=initial_trust)
    episode_id = f"{spec.name}-{routing.name}-s{seed}"
    if engine == "model":
        from trustroute.harness.simulation.model_engine import run_model_episode

        return run_model_episode(setup, routing, synthetic, episode_id, seed)
    from trustroute.harness.simulation.episode import run_episode as run_sumo

    return run_sumo(setup, routing, synthetic, episode_id, seed, rrd_path=Path(rrd) if rrd else None)


def run_study(config: StudyConfig | dict | PathLike, out: PathLike | None = None, *, workers: int = 1,
              engine: str | None = None, scheduler: str | None = None,
              progress: bool = False) -> StudyRun:
    """Run (or resume) a simulated within-subject study and consolidate its dataset.

    config: a study config file (docs/formats/study_config.md), the same content as a dict
    ({"study": {...}, "population": {...}}; relative paths resolve against the current directory)
    or a StudyConfig. out: the study directory (default: the config's `output`, else
    studies/<name>). workers: local processes (1: this process). engine: override the config's
    engine ("sumo" or "model"). scheduler: a Dask scheduler address or "local". Returns the run;
    `run.study_dir` holds the dataset (docs/dataset.md) that `analyze` reads.
    """
    from trustroute.harness.study.config import (
        StudyConfig,
        load_study_config,
        study_config_from_dict,
        study_directory,
    )
    from trustroute.harness.study.runner import run_and_consolidate

    if isinstance(config, dict):
        config = study_config_from_dict(config, "<study dict>", Path.cwd())
    elif not isinstance(config, StudyConfig):
        config = load_study_config(config)
    config = config.with_overrides(engine=engine)
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    run, _ = run_and_consolidate(config, study_directory(config, None if out is None else str(out)),
                                 workers, scheduler, progress=progress, echo=lambda line: None)
    return run


def analyze(study_dir: PathLike, *, belief_source: str = "filter", report: bool = False) -> StudyAnalysis:
    """Per spec and condition of a study directory: n, satisfaction rate with its CI, mean trust,
    the policies' exact values, and the paired aware-vs-free tests (`analysis.cells`,
    `analysis.paired`, `analysis.to_dict()`).

    belief_source: evaluate the spec on the AV's filter beliefs ("filter") or on beliefs induced
    from the reported trust ("reported"). report: also write report.md, report.html and the plots
    into the study directory (otherwise nothing is written).
    """
    from trustroute.analysis.study.analysis import study_analysis

    analysis = study_analysis(Path(study_dir), belief_source=belief_source)
    if report:
        from trustroute.analysis.study.report import write_report

        write_report(Path(study_dir), analysis=analysis)
    return analysis
