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

import functools
import os
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from trustroute.core import defaults
from trustroute.core.errors import InputError, keyword_names
from trustroute.core.wording import shown_value

if TYPE_CHECKING:
    from trustroute.analysis.study.analysis import StudyAnalysis
    from trustroute.app.runs import EpisodeSettings
    from trustroute.app.synthesis import EvaluationOutcome, SynthesisSettings
    from trustroute.harness.simulation.episode import EpisodeRecord
    from trustroute.harness.study.config import StudyConfig
    from trustroute.harness.study.runner import StudyRun
    from trustroute.networks.town import Town
    from trustroute.participants.driver_model import DriverModel
    from trustroute.participants.driver_population import DriverPopulation
    from trustroute.policies.belief.problem import Problem
    from trustroute.policies.evaluation.settings import EvaluationSettings
    from trustroute.policies.logic.spec import Spec
    from trustroute.policies.routing.protocol import RoutingPolicy
    from trustroute.policies.synthesis.population import Objective, PopulationSynthesis
    from trustroute.policies.synthesis.result import SynthesisResult

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
Call = TypeVar("Call", bound=Callable[..., Any])


def _door(function: Call) -> Call:
    """An API call whose InputErrors name its keyword arguments where the messages, shared with
    the CLI, name its flags (`keyword_names`: "--initial-trust" is `initial_trust`)."""
    @functools.wraps(function)
    def door(*args: Any, **kwargs: Any) -> Any:
        try:
            return function(*args, **kwargs)
        except InputError as error:
            raise keyword_names(error) from None

    return door  # type: ignore[return-value]


@_door
def load_town(path: PathLike | None = None) -> Town:
    """The validated town of a town file or packaged town name (docs/formats/town.md); the packaged
    town when omitted."""
    from trustroute.app.inputs import town_of

    return town_of(path)


@_door
def load_driver_model(path: PathLike | None = None) -> DriverModel:
    """The validated driver model of a file or packaged name (docs/formats/driver_model.md); the
    packaged one when omitted."""
    from trustroute.app.inputs import driver_of

    return driver_of(path)


@_door
def load_spec(spec: PathLike, town: Town | PathLike | None = None) -> Spec:
    """The validated scLDTL spec of a spec file (docs/formats/spec.md), checked against `town`
    (default: the town a packaged spec is written for, else the packaged town).

    `spec` is a file path or the name of a packaged spec ("phi1", "phi2", "phi1_strict",
    "phi2_strict", "phi1_trust", "city5", "csomor5"); an existing file of that name wins
    (trustroute/core/packaged.py, as for towns, driver models and populations).
    """
    from trustroute.app.inputs import spec_of, town_of

    return spec_of(spec, town_of(town, spec))


def _compiled(spec: Spec | PathLike, town: Town | PathLike | None, driver: DriverModel | PathLike | None,
              population: DriverPopulation | PathLike | None = None) -> Problem:
    """The compiled problem of the arguments, the packaged defaults filled in (trustroute/app)."""
    from trustroute.app.problem import load_problem

    return load_problem(spec, town, driver, population)


@_door
def synthesize(spec: Spec | PathLike, town: Town | PathLike | None = None,
               driver: DriverModel | PathLike | None = None, *, settings: SynthesisSettings | None = None,
               out: PathLike | None = None, population: DriverPopulation | PathLike | None = None,
               objective: Objective = defaults.OBJECTIVE,
               **options: Any) -> SynthesisResult | PopulationSynthesis:
    """A trust-aware policy for `spec` with certified bounds `result.lower <= Pr_max <= result.upper`.

    settings: how the search runs, a `trustroute.app.synthesis.SynthesisSettings` (default: its
    defaults, `trustroute synth`'s); any of its fields may instead be given by keyword, over
    `settings`: horizon (at most this many junctions; None: unbounded), tau (stop when
    upper - lower <= tau), time_limit (seconds, about), belief_rule (the AV's filter, exact
    "bayes" or the authors' "paper" update, docs/model.md), ... out: also write the policy file
    there (docs/formats/policy_file.md); checked before any work, as `trustroute synth --out`
    checks it (writable, no input file, in no package). `result.policy` is the policy; `result.lower` is its
    exact value; `result.fallback_only` says what drives when the policy has no synthesized
    decision (None when it has one), as `trustroute synth` warns.

    population: a driver population (object, file or packaged name; instead of `driver`): synthesis
    for its mixture of driver types under `objective` ("bayes": the prior-weighted value, "robust":
    the worst type's; docs/driver_types.md), for any spec, trust-state atoms included. It returns a
    PopulationSynthesis: `lower <= optimum <= upper` of the objective, `type_values` the returned
    policy's value per type, `result` its SynthesisResult (`result.policy` the policy).
    """
    from trustroute.app.synthesis import (
        SynthesisSettings,
        check_policy_out,
        check_synthesis_options,
        synthesize_population,
        synthesize_single,
    )
    from trustroute.core.ranges import check_time_limit
    from trustroute.core.settings import with_options

    chosen = with_options(settings, SynthesisSettings(), options, "synthesize")
    check_time_limit(chosen.time_limit)
    check_synthesis_options(population is not None, objective, chosen.clusters)
    if out is not None:   # before any work, as `trustroute synth --out`
        check_policy_out(out, {"spec": spec, "--town": town, "--driver": driver, "--population": population})
    problem = _compiled(spec, town, driver, population)
    if problem.population is not None:
        return synthesize_population(problem, objective, chosen, out)
    return synthesize_single(problem, chosen, out)


def _policy(policy: PolicyLike, problem: Problem, cache_dir: PathLike | None) -> RoutingPolicy:
    """A RoutingPolicy from "free", "aware", "robust"/"bayes" (a population's), a policy file path,
    a SynthesisResult or a policy."""
    from trustroute.app.policy import PolicySettings, policy_for
    from trustroute.policies.routing.protocol import RoutingPolicy
    from trustroute.policies.synthesis.result import SynthesisResult

    if isinstance(policy, str | Path):
        return policy_for(problem, policy, PolicySettings(cache_dir=cache_dir))
    if isinstance(policy, SynthesisResult):
        return policy.policy
    if not isinstance(policy, RoutingPolicy):
        raise InputError("policy", "", "expected a policy name ('free', 'aware', 'robust', 'bayes'), "
                         f"a policy file, a SynthesisResult or a RoutingPolicy, got {shown_value(policy)}",
                         "pass one of those")
    return policy


@_door
def evaluate(spec: Spec | PathLike, policy: PolicyLike = defaults.POLICY,
             town: Town | PathLike | None = None, driver: DriverModel | PathLike | None = None, *,
             settings: EvaluationSettings | None = None, cache_dir: PathLike | None = None,
             population: DriverPopulation | PathLike | None = None,
             **options: Any) -> EvaluationOutcome:
    """The exact probability that `policy` satisfies `spec`, its expected final trust and how
    episodes end (no sampling; `value.lower`/`value.upper` certify it): an Evaluation
    (`trustroute.app.synthesis.EvaluationOutcome`) whose `fallback_only` says what drives when the
    policy is a synthesized one with no decision (None when it has one), as `trustroute evaluate`
    warns and `trustroute.synthesize(...).fallback_only` says.

    policy: "free" (the trust-free shortest route), "aware" (synthesized for 20 junctions and
    cached in `cache_dir`), a policy file, a SynthesisResult or any RoutingPolicy.
    settings: how the episodes unfold, a `trustroute.policies.evaluation.settings.EvaluationSettings`
    (default: its defaults, `trustroute evaluate`'s); any of its fields may instead be given by
    keyword, over `settings`: fallback_after (the study's rule, the shortest completion after that
    many junctions; None: the policy as given), max_junctions (the episode cap, docs/model.md,
    "Episodes"), belief_rule, ...
    population: a driver population (instead of `driver`): the value over its mixture of types,
    the AV filtering with its type-aware model; policy "free", "robust", "bayes" or a population
    policy file (docs/driver_types.md), as `trustroute evaluate --population`. `value.type_values`
    is then the policy's certified value per driver type (None without a population), as a
    population synthesis' `type_values`.
    """
    from trustroute.app.synthesis import EvaluationSettings, evaluate_problem
    from trustroute.core.settings import with_options

    chosen = with_options(settings, EvaluationSettings(), options, "evaluate")
    problem = _compiled(spec, town, driver, population)
    return evaluate_problem(problem, lambda: _policy(policy, problem, cache_dir), chosen)


@_door
def run_episode(spec: Spec | PathLike, policy: PolicyLike = defaults.POLICY,
                town: Town | PathLike | None = None, driver: DriverModel | PathLike | None = None, *,
                settings: EpisodeSettings | None = None, cache_dir: PathLike | None = None,
                population: DriverPopulation | PathLike | None = None, **options: Any) -> EpisodeRecord:
    """One episode of `spec` with `policy` and a synthetic driver drawn from `driver`.

    settings: how the episode runs, a `trustroute.app.runs.EpisodeSettings`; any of its fields may
    instead be given by keyword, over `settings`: engine ("sumo", libsumo: incidents, takeovers
    and performance measured in the simulation, or "model": the trust POMDP alone, no SUMO), seed
    (SUMO's seed and the driver's Generator seed), initial_trust (the driver's initial trust;
    default: drawn from the model), rrd (also write a Rerun recording there; SUMO engine only),
    net (the SUMO net; SUMO engine only), sumo, ... policy: as for `evaluate` ("robust"/"bayes"
    with a population). population: a driver population (instead of `driver`): the driver's type
    is drawn from it (seeded) and the AV filters with its type-aware model. Returns the logs:
    `record.summary` (dict), `record.roads`, `record.kinematics`, `record.incidents` (DataFrames,
    docs/dataset.md); the episode follows the study's rules (20-junction fallback, 60-junction cap).
    """
    from trustroute.app.runs import EpisodeSettings, run_one_episode
    from trustroute.core.settings import with_options

    chosen = with_options(settings, EpisodeSettings(option="initial_trust"), options, "run_episode")
    problem = _compiled(spec, town, driver, population)
    routing = _policy(policy, problem, cache_dir)
    chosen = replace(chosen, rrd=Path(chosen.rrd) if chosen.rrd else None)
    return run_one_episode(problem, routing, chosen).record


@_door
def run_study(config: StudyConfig | dict | PathLike, out: PathLike | None = None, *,
              workers: int | None = defaults.WORKERS, engine: str | None = None, scheduler: str | None = None,
              attempts: int = defaults.ATTEMPTS, progress: bool = False) -> StudyRun:
    """Run (or resume) a simulated within-subject study and consolidate its dataset.

    config: a study config file (docs/formats/study_config.md), the same content as a dict
    ({"study": {...}, "population": {...}}; relative paths resolve against the current directory)
    or a StudyConfig. out: the study directory (default: the config's `output`, else
    studies/<name>). workers: local processes, 1 (this process) to 256 (default: the CPU count, as
    `trustroute study`; every draw is seeded, so the count never changes the data). engine:
    override the config's engine ("sumo" or "model"). scheduler: a Dask scheduler address or
    "local". attempts: runs of a failing episode at most, 1 to 10 (the first and its retries; one
    that failed on its own bad input, an InputError such as TrafficJam, runs once).
    Returns the run; `run.study_dir` holds the dataset (docs/dataset.md) that `analyze` reads.
    """
    from trustroute.core.ranges import study_workers
    from trustroute.harness.study.config import (
        StudyConfig,
        load_study_config,
        study_config_from_dict,
        study_directory,
    )
    from trustroute.harness.study.runner import run_and_consolidate

    processes = study_workers(workers)
    if isinstance(config, dict):
        config = study_config_from_dict(config, "<study dict>", Path.cwd())
    elif isinstance(config, str | os.PathLike):
        config = load_study_config(config)
    elif not isinstance(config, StudyConfig):
        raise InputError("config", "", "expected a study config file, a dict or a StudyConfig, "
                         f"got {shown_value(config)}", "pass one of those (docs/formats/study_config.md)")
    config = config.with_overrides(engine=engine)
    run, _ = run_and_consolidate(config, study_directory(config, None if out is None else str(out)),
                                 processes, scheduler, progress=progress, echo=lambda line: None,
                                 attempts=attempts)
    return run


@_door
def analyze(study_dir: PathLike, *, belief_source: str | None = defaults.BELIEF_SOURCE,
            report: bool | None = None, out: PathLike | None = None) -> StudyAnalysis:
    """Per spec and condition of a study directory: n, satisfaction rate with its CI, mean trust,
    the policies' exact values, the paired tests of every pair of conditions with Holm-adjusted
    p-values, and every comparison on every belief source (`analysis.cells`, `analysis.paired`,
    `analysis.sensitivity`, `analysis.to_dict()`).

    belief_source: the beliefs the specs are evaluated on ("true", "reported", "reference" or
    "filter"); None: the study's primary source, the same default as `trustroute analyze`
    (analysis/belief_sources.py `default_belief_source`). report: also write report.md,
    report.html and the plots into `out` (default: the study directory); by default nothing is
    written unless `out` is given, as with `trustroute analyze --json` (the analysis is handed over
    as data; the command printing its tables rewrites the report, trustroute/core/defaults.py
    `REPORT_WITH_DATA`). out: the report's folder, checked before any work when the report is
    written there; with report=False nothing is written, so `out` is neither used nor checked (as
    `trustroute analyze --no-report --out`: one rule, trustroute/app/analysis.py `report_wanted`).
    `study_dir` may be a package `trustroute export` wrote: its figures are the study's, and its
    report is written only into `out`.
    """
    from trustroute.app.analysis import analyze_study, report_wanted

    folder = None if out is None else Path(out)
    wanted = report_wanted(Path(study_dir), report, defaults.REPORT_WITH_DATA, folder)
    return analyze_study(Path(study_dir), belief_source, wanted, folder).analysis
