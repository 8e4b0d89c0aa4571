"""Synthesis and exact evaluation of a compiled problem, for the API and the CLI alike: the
settings validated once, the problem's case choosing the method (policies/synthesize_spec.py), the
policy file written where asked."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields, replace
from os import PathLike
from pathlib import Path

from trustroute.core import defaults, ranges
from trustroute.core.errors import InputError
from trustroute.core.fields import OneOf, check_value
from trustroute.core.output_files import check_output_file
from trustroute.core.ranges import check_time_limit, keep_checked
from trustroute.core.wording import shown_value
from trustroute.policies.belief.problem import Problem
from trustroute.policies.evaluation.plain import Evaluation
from trustroute.policies.evaluation.plain import evaluate as evaluate_plain
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.evaluation.trust_state import evaluate_joint, evaluate_joint_by_type
from trustroute.policies.model.trust_pomdp import BeliefRule, checked_belief_rule
from trustroute.policies.resolve import is_objective, phase_lines, synthesis_progress
from trustroute.policies.routing.aware_table import BeliefTablePolicy
from trustroute.policies.routing.decision_tables import fallback_only as fallback_only
from trustroute.policies.routing.decision_tables import fallback_warning as fallback_warning
from trustroute.policies.routing.files import array_path, save_policy
from trustroute.policies.routing.free import baseline_route, trust_free_policy
from trustroute.policies.routing.protocol import RoutingPolicy
from trustroute.policies.synthesis.belief_synthesis import unbounded_schedule_note
from trustroute.policies.synthesis.cluster_policy import CLUSTER_CAPS, own_cap
from trustroute.policies.synthesis.population import (
    Objective,
    PopulationSynthesis,
    TypeValue,
    document_entries,
    per_type_values,
    policy_name,
    summary,
)
from trustroute.policies.synthesis.refinement import reached_node_budget
from trustroute.policies.synthesis.result import SearchRun, SynthesisResult, SynthesisStats
from trustroute.policies.synthesis.rounding import certify, problem_rounding
from trustroute.policies.synthesis.settings import CLUSTER_MODES as SEARCH_CLUSTER_MODES
from trustroute.policies.synthesis.settings import SynthesisSettings as SearchSettings
from trustroute.policies.synthesize_spec import synthesize_for_population, synthesize_problem
from trustroute.policies.trust_state_synthesis.population import certified_type_values
from trustroute.policies.trust_state_synthesis.synthesis import joint_cap_note
from trustroute.policies.work_clock import CAPS, WorkClock, installed, stopped_by, work_clock


def belief_rule_named(name: str) -> BeliefRule:
    """The AV filter called `name` ("bayes" or "paper"), checked."""
    return checked_belief_rule(name)


CLUSTER_MODES = OneOf(choices=defaults.CLUSTER_MODES, noun="clusters mode")


@dataclass(frozen=True)
class SynthesisSettings(SearchSettings):
    """The search's settings (policies/synthesis/settings.py) as the doors take them: the doors'
    defaults, each number in the range the CLI takes (trustroute/core/ranges.py; an InputError
    naming the option), and whether progress shows on stderr. An instance is passed down to the
    search as it is."""

    tau: float = defaults.TAU
    time_limit: float = defaults.TIME_LIMIT
    work_limit: int | None = defaults.WORK_LIMIT
    horizon: int | None = defaults.SYNTH_HORIZON
    belief_rule: BeliefRule = defaults.BELIEF_RULE
    clusters: str = defaults.CLUSTERS
    progress: bool = False

    def __post_init__(self) -> None:
        keep_checked(self, {"tau": ranges.TAU, "horizon": ranges.HORIZON, "work_limit": ranges.WORK_LIMIT,
                            "node_budget": ranges.NODE_BUDGET}, optional=("horizon", "work_limit"))
        object.__setattr__(self, "belief_rule", checked_belief_rule(self.belief_rule))
        if self.clusters not in SEARCH_CLUSTER_MODES:   # the search's own modes are set past the doors
            check_value(self.clusters, CLUSTER_MODES, "--clusters", "")
        super().__post_init__()


def run_stop(result: SynthesisResult, clock: WorkClock | None) -> str:
    """What ended one synthesis run (work_clock.stopped_by): its convergence, its search's node
    budget, a cap of its own (synthesis/cluster_policy.py `own_cap`) or the limit of `clock`."""
    return stopped_by(result.stats.converged, clock, reached_node_budget(result.stats), own_cap(result))


def synthesize_single(problem: Problem, settings: SynthesisSettings,
                      out: str | Path | None = None) -> SynthesisResult:
    """A policy for a one-model problem with bounds; its file written at `out` when given
    (`written_policy` names the file)."""
    with work_clock(settings.work_limit, settings.time_limit) as limit:
        clock = installed()
        with synthesis_progress(f"synthesizing {problem.spec.name}", settings.progress) as on_iteration:
            result = synthesize_problem(problem, replace(settings, time_limit=limit),
                                        on_iteration=on_iteration)
    result = replace(result, stopped_by=run_stop(result, clock))
    if out is not None:
        save_policy(result, out, problem.town, problem.driver, problem.spec)
    return result


def check_synthesis_options(population: bool, objective: str, clusters: str) -> Objective:
    """The options a synthesis takes for whom it is for, checked by every door before any work: an
    objective weighs a `population`'s driver types, cluster policies are for a single model. The
    objective, checked."""
    if not is_objective(objective):
        raise InputError("--objective", "", f"unknown objective {shown_value(objective)}",
                         "use 'bayes' or 'robust'")
    check_value(clusters, CLUSTER_MODES, "--clusters", "")
    if population and clusters != "auto":
        raise InputError("--clusters", "", "cluster policies apply to a single driver model (--driver)",
                         "drop --clusters, or synthesize for --driver instead of --population")
    if not population and objective != defaults.OBJECTIVE:
        raise InputError("--objective", "", f"--objective {objective} needs the types to weigh",
                         "add --population FILE (the driver types)")
    return objective


def synthesize_population(problem: Problem, objective: str, settings: SynthesisSettings,
                          out: str | Path | None = None) -> PopulationSynthesis:
    """A policy for a population problem under `objective` ("bayes" or "robust"); its file
    written at `out` when given."""
    population = problem.population
    assert population is not None
    checked = check_synthesis_options(True, objective, settings.clusters)
    spec = problem.given_spec
    description = f"synthesizing {spec.name} ({objective}, {population.n_types} types)"
    with work_clock(settings.work_limit, settings.time_limit) as limit, \
            synthesis_progress(description, settings.progress) as on_iteration:
        clock = installed()
        found = synthesize_for_population(problem.town, population, spec, checked,
                                          replace(settings, time_limit=limit),
                                          population_source=population.source_path,
                                          on_iteration=on_iteration,
                                          on_phase=phase_lines("synth", settings.progress))
    ended = population_stop(found, clock, settings.tau)
    found = replace(found, result=replace(found.result, stopped_by=ended))
    if out is not None:
        save_policy(found.result, out, problem.town, found.pomdp.driver, found.spec,
                    population=document_entries(found), name=policy_name(found))
    return found


def reached_tau(found: PopulationSynthesis, tau: float) -> bool:
    """Whether a population synthesis converged: the Bayes objective's bounds are its one search's,
    converged on the values it computed (the reported ones are rounded outward,
    policies/synthesis/rounding.py); the robust objective's gap is its certified one."""
    return found.result.stats.converged if found.objective == "bayes" else found.gap <= tau


def population_stop(found: PopulationSynthesis, clock: WorkClock | None, tau: float) -> str:
    """What ended a population synthesis (work_clock.stopped_by): the Bayes objective's one search
    says so. The robust objective above tau names the limit that skipped a candidate prior or cut a
    run short; else, every prior run and no run cut, the node budget if a run's search stopped at
    it, or the candidate grid (its gap is the grid search's: more time would not narrow it)."""
    if found.objective == "bayes":
        return run_stop(found.result, clock)
    whole = found.candidates_skipped == 0 and found.runs_cut == 0
    return stopped_by(reached_tau(found, tau), clock, whole and found.runs_at_node_budget > 0,
                      "candidate grid" if whole else None)


def certified(problem: Problem, value: Evaluation) -> Evaluation:
    """An evaluation's computed [lower, upper] rounded outward for its histories of at most
    `max_junctions` steps (policies/synthesis/rounding.py, `certify`), so that it holds exactly."""
    return certify(value, problem_rounding(problem))


def check_evaluation(problem: Problem, settings: EvaluationSettings) -> None:
    """The limits an exact evaluation of `problem` takes, checked where a door is given them (the
    CLI before it makes the policy, the API before it evaluates): the pruning limits are not used
    for a population, a time limit only for specs with trust-state atoms (the others are
    evaluated exactly in full)."""
    if problem.population is not None and (settings.max_nodes is not None or settings.time_limit is not None):
        raise InputError("--max-nodes" if settings.max_nodes is not None else "--time-limit", "",
                         "the pruning limits are not used for a driver population",
                         "drop --max-nodes and --time-limit, or evaluate for --driver")
    if settings.time_limit is None:
        return
    check_time_limit(settings.time_limit)
    if not problem.dfa_hidden:
        raise InputError("--time-limit", "", "applies to specs with trust-state atoms only (the others "
                         "are evaluated exactly in full)", "drop --time-limit")


def evaluate_single(problem: Problem, policy: RoutingPolicy, settings: EvaluationSettings) -> Evaluation:
    """The certified value of `policy` on a one-model problem (the joint unfolding when the DFA
    state is hidden, the plain one otherwise: evaluate_joint chooses)."""
    return certified(problem, evaluate_joint(problem.pomdp, problem.spec, policy, settings))


def evaluate_population(problem: Problem, policy: RoutingPolicy,
                        settings: EvaluationSettings) -> tuple[Evaluation, tuple[TypeValue, ...]]:
    """The certified value of `policy` over a population problem's mixture, and per driver type."""
    population = problem.population
    assert population is not None
    rule, cap, after = settings.belief_rule, settings.max_junctions, settings.fallback_after
    if problem.dfa_hidden:
        # The DFA state is hidden: one unfolding over ((type, trust), q) gives every type's value.
        value, bounds = evaluate_joint_by_type(problem.pomdp, problem.spec, policy, settings)
        return certified(problem, value), certified_type_values(problem, bounds, cap)
    value = evaluate_plain(problem.pomdp, problem.spec, policy, settings)
    return (certified(problem, value),
            tuple(per_type_values(problem.pomdp, problem.spec, policy, population, cap, rule, after)))


@dataclass(frozen=True)
class EvaluationOutcome(Evaluation):
    """An evaluation as every door reports it (`evaluate_problem`): the Evaluation, and
    type_values: the policy's certified value per driver type when the problem has a population
        (None without one), as a population synthesis gives its policy's
        (`PopulationSynthesis.type_values`);
    fallback_only: what drives everywhere, in words, when the policy is a synthesized one with no
        decision row (`fallback_only`), so that its values are the fallback's; None otherwise, as
        `SynthesisResult.fallback_only`.
    `to_dict()` is the Evaluation's with each of these two that is not None after it: `type_values`
    as a list of `TypeValue.to_dict()`, `fallback_only` as its text (`trustroute evaluate` reshapes
    them for its JSON: harness/commands/synth.py, `_evaluation_output`)."""

    type_values: tuple[TypeValue, ...] | None = None
    fallback_only: str | None = None

    @classmethod
    def of(cls, value: Evaluation, type_values: tuple[TypeValue, ...] | None,
           fallback: str | None) -> EvaluationOutcome:
        shared = {f.name: getattr(value, f.name) for f in fields(Evaluation)}
        return cls(**shared, type_values=type_values, fallback_only=fallback)

    def to_dict(self) -> dict:
        out = super().to_dict()
        del out["type_values"], out["fallback_only"]   # asdict's, placed below as they serialise
        if self.type_values is not None:
            out["type_values"] = [t.to_dict() for t in self.type_values]
        if self.fallback_only is not None:
            out["fallback_only"] = self.fallback_only
        return out


def evaluate_problem(problem: Problem, make_policy: Callable[[], RoutingPolicy],
                     settings: EvaluationSettings) -> EvaluationOutcome:
    """The certified value of the policy `make_policy` gives, on `problem` (over the population's
    mixture of types when it has one, and per type), and whether that policy is only its fallback:
    the limits checked first (`check_evaluation`), so that a bad one is refused before a policy is
    synthesized or read."""
    check_evaluation(problem, settings)
    policy = make_policy()
    if problem.population is not None:
        value, types = evaluate_population(problem, policy, settings)
    else:
        value, types = evaluate_single(problem, policy, settings), None
    return EvaluationOutcome.of(value, types, fallback_only(policy))


@dataclass(frozen=True)
class Baseline:
    route: list[str]
    length_m: float
    value: Evaluation


def baseline(problem: Problem, belief_rule: BeliefRule = defaults.BELIEF_RULE) -> Baseline:
    """The trust-free baseline: the shortest route completing the spec's state-only task, and its
    certified value without the fallback (as `evaluate` gives it: the joint unfolding for a spec
    with trust-state atoms)."""
    town, spec = problem.town, problem.spec
    route = baseline_route(town, spec)
    settings = EvaluationSettings(fallback_after=None, belief_rule=checked_belief_rule(belief_rule))
    value = evaluate_single(problem, trust_free_policy(town, spec), settings)
    return Baseline(route=route, length_m=town.route_length(route), value=value)


def policy_arrays(path: str | Path) -> Path:
    """The array file written beside a policy file."""
    return array_path(path)


def check_policy_out(out: str | Path, reads: Mapping[str, object]) -> None:
    """Every door's check of the policy file `out` of a synthesis, before any work: it and its array
    file beside it can be written, lie in no package (published read-only) and are none of the files
    the synthesis `reads` (argument name -> value; a value that is no path, an object passed
    instead of a file, reads no file)."""
    files = {name: value if isinstance(value, str) else Path(value)
             for name, value in reads.items() if isinstance(value, str | PathLike)}
    check_output_file(out, "--out", "policy file", files)
    check_output_file(policy_arrays(out), "--out", "policy array file (.npz beside it)", files)


def stop_line(stopped_by: str, tau: float, converged: bool) -> str:
    """Why the run ended, in the word `--json` gives as "stopped_by" (policies/work_clock.py,
    `stopped_by`): the gap reached tau, or a limit or cap came first; or (`converged`, under a
    work limit) the gap reached tau but the wall clock passed the time limit on the way."""
    if stopped_by == "convergence":
        return f"stopped by: convergence (the gap reached tau = {tau:g})"
    if converged:
        return (f"stopped by: {stopped_by}, though the gap reached tau = {tau:g}: the wall clock passed "
                "the time limit under the work limit, so the result may depend on the machine's load")
    return f"stopped by: {stopped_by}, before the gap reached tau = {tau:g}"


def stop_notes(result: SynthesisResult, tau: float, converged: bool) -> list[str]:
    """What a reader should know of how the run ended: why (`stop_line`; `converged`: whether the
    gap reached tau); then a search stopped at its node budget, which more time would not have
    moved; bounds that are the cluster policies' at their largest cap, those a trust-state
    synthesis' own cap left (`joint_cap_note`), or a robust objective's whole candidate grid."""
    said = [] if result.stopped_by is None else [stop_line(result.stopped_by, tau, converged)]
    return said + _stop_explained(result)


def _stop_explained(result: SynthesisResult) -> list[str]:
    """The note on a stop by a node budget or a cap of the method's own (none for the others)."""
    if result.stopped_by == "candidate grid":
        return ["every candidate prior of the grid ran and no run was cut by its limit (each converged or "
                "ended at a cap of its own): the gap is the grid search's (it compares the grid's priors, "
                "not all policies), and a longer --time-limit would not narrow it"]
    if result.stopped_by == "cluster cap":
        return [f"the bounds are the cluster policies' at their largest cap ({CLUSTER_CAPS[-1]} clusters "
                "per junction, road and automaton state), tighter than the search's before them: a longer "
                "--time-limit lengthens that search and need not move them"]
    if result.stopped_by in CAPS and isinstance(result.stats, SynthesisStats):
        return [unbounded_schedule_note(result.seconds)]
    if result.stopped_by in CAPS:
        return [joint_cap_note(result.stopped_by, result.seconds)]
    if result.stopped_by != "node budget":
        return []
    remedy = ("before its time limit: a longer --time-limit would not tighten these bounds, a larger "
              "--node-budget may (about 1 kB of memory a node)")
    if not reached_node_budget(result.stats):   # a robust objective's run, not the returned policy's
        return [f"a run of the robust objective stopped at its node budget {remedy}"]
    nodes = max(run.nodes for run in result.stats.runs if isinstance(run, SearchRun))
    return [f"the search stopped at its node budget ({nodes:,} nodes) after {result.seconds:.1f} s, {remedy}"]


def bounds_notes(result: SynthesisResult, tau: float) -> list[str]:
    """What a reader of the bounds should know: how the run ended, a cluster policy."""
    lines = stop_notes(result, tau, result.stats.converged)
    table = result.policy.table if isinstance(result.policy, BeliefTablePolicy) else None
    boxes = table.boxes if table is not None else None
    if boxes is not None and boxes.rows:
        lines.append(f"a cluster policy: {boxes.rows} box rows, beliefs enclosed in boxes "
                     "(docs/synthesis.md, \"Cluster policies\")")
    return lines


def population_summary(found: PopulationSynthesis) -> dict:
    """The population synthesis's summary (types, values, prior) as the policy file records it."""
    return summary(found)
