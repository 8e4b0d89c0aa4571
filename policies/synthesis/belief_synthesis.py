"""Policy synthesis with certified bounds: lower <= Pr_max(spec) <= upper (docs/model.md, "What L and U
mean"). `synthesize` is the entry point; it schedules the phases below within its time limit
(budget.py) and reports typed statistics (result.py).

Method (bounded heuristic search over the product belief MDP, with a sound abstraction at the frontier):

* The exact product belief MDP is unfolded from (start, initial belief, q_0) as an AND-OR graph
  (node store: belief_graph.py; expansion and backups: expansion.py): identical beliefs at the
  same depth are merged, never approximated. Every node carries [L, U]: open nodes U from the
  suffix abstraction (upper_bound.py), L from the trust-free completion (open_node_bounds.py,
  completion_value.py); expanded nodes by Bellman backups.
* Refinement (AO*/HSVI style, refinement.py): per round, expand the open nodes carrying the most
  of the root's gap and look ahead along their upper-greedy moves; bound (Bayes) or free-expand
  (authors' rule) the FRONTIER nodes the returned policy reaches; until U - L <= tau at the root,
  the frontier is exhausted, or the time limit.
* The returned policy (policy_extraction.py) takes at every EXPANDED node the action maximising L
  among those the hold rule allows (ties: strict value, then U) and drives the free completion
  everywhere else (the exact-belief acting rule of policies.routing.aware_table.BeliefTablePolicy):
  the trust-free completion of the state-only task, then the shortest route back to what the DFA
  still needs, every label allowed (policies/routing/free.py, `free_completion`). After the last
  round the completions it reaches are bounded (Bayes) or closed (authors' rule), so `lower` is a
  lower bound of that policy's value (its exact value under the authors' rule). Where a
  completion bound is used, rows its route can reach may leave the free move only for a move
  worth at least the completion's upper bound (the hold rule, BeliefSearch.choose in
  expansion.py), which keeps the bound sound (docs/synthesis.md, "Open nodes and the acting rule").

Horizon H: at most H junctions (the study measures "policy, then fallback after 20", so H = 20 is
the natural companion). Unbounded (horizon=None): upper is the abstraction's least fixed point with
end components collapsed (policies/synthesis/end_components.py), tightened by a search of the
unbounded problem itself (open nodes, including those deeper than UNBOUNDED_DEPTH, valued by that
bound); lower is the best of that search and bounded searches with growing H (their policies are
policies for the unbounded problem too, worth at least their bounded value).

Cluster policies (Bayes rule; policies/synthesis/cluster_policy.py, docs/synthesis.md "Cluster
policies"): the whole product solved with beliefs enclosed in boxes, a policy of box rows with its
own certified [L, U]. `synthesize` runs them before the search on large problems and after an
unconverged search elsewhere (CLUSTER_MODES), and returns the better L with its policy and the
smaller U.

Labels at thresholds are decided exactly where floating point cannot decide them
(policies/belief/exact_labels.py; docs/synthesis.md, "Labels at thresholds"). Horizons shorter
than the road x DFA graph distance to acceptance are answered without search (L = U = 0).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TypeAlias

import numpy as np

from trustroute.policies.belief.product_mdp import ProductTables, build_product
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.routing.aware_table import BeliefTablePolicy, PolicyTable
from trustroute.policies.routing.free import state_only_task
from trustroute.policies.synthesis.belief_cells import ObservationSymbols, observation_symbols, suffix_cells
from trustroute.policies.synthesis.budget import TimeBudget
from trustroute.policies.synthesis.cluster_policy import ClusterSolution, best_cluster_solution
from trustroute.policies.synthesis.end_components import UnboundedBound, unbounded_bound
from trustroute.policies.synthesis.expansion import AUTO_TREE_LEAVES, UNBOUNDED_DEPTH
from trustroute.policies.synthesis.open_node_bounds import completion_tree_leaves
from trustroute.policies.synthesis.refinement import bounded_search
from trustroute.policies.synthesis.result import (
    ClusterAttempt,
    ClusterRun,
    GraphDistanceRun,
    Run,
    SearchRun,
    SynthesisResult,
    SynthesisStats,
)
from trustroute.policies.synthesis.rounding import model_rounding, relative_margin, rounded_down, widen
from trustroute.policies.synthesis.settings import DEFAULT_SYNTHESIS, SynthesisSettings
from trustroute.policies.synthesis.upper_bound import (
    Abstraction,
    acceptance_distance,
    automatic_suffix_length,
    bounded_suffix_length,
    build_abstraction,
    unbounded_suffix_length,
)
from trustroute.policies.work_clock import work_clock

UNBOUNDED_HORIZONS = (20, 30, 40, 60, 80, 120, 160)
UNBOUNDED_BOUND_SHARE = 0.3  # share of the time limit the end-component bound may take
UNBOUNDED_SEARCH_SHARE = 0.25  # share of the time left the search of the unbounded problem may take
FINISH_SHARE = 0.04          # share of the time limit kept for finishing after the last check
# Cluster policies (cluster_policy.py) under the Bayes rule (settings.py's CLUSTER_MODES): "auto"
# before the search where open nodes would get cluster bounds (the free route's observation tree
# exceeds AUTO_TREE_LEAVES), and after it elsewhere when the search ends with a gap above tau (it
# then has SEARCH_SHARE of the time); "on" always before the search; "off" never.
CLUSTER_SHARE = 0.75          # share of the time limit the cluster policies may take before the search
SEARCH_SHARE = 0.5            # share of the time limit of a search that cluster policies may follow
# unbounded: cluster policies for these junction counts beyond the shortest acceptance, in turn
UNBOUNDED_CLUSTER_SLACK = (10, 20, 30, 45)
UNBOUNDED_CLUSTER_CAPS = (16, 64, 256)

BeliefSynthesis: TypeAlias = SynthesisResult[BeliefTablePolicy, SynthesisStats]


@dataclass(eq=False)
class _Progress:
    """What the progress callback is told after each round: the largest L of any run so far (each a
    lower bound of the value of the policy that run returns, and the synthesis returns the best) and
    the smallest U so far of the problem asked (a search within fewer junctions than the unbounded
    problem bounds another probability, so its U is not told), the bounds the result will show."""

    on_iteration: Callable[[float, float], None] | None
    lower: float = 0.0
    upper: float = 1.0

    def narrow(self, upper: float) -> None:
        self.upper = min(self.upper, upper)

    def report(self, lower: float, upper: float | None) -> None:
        self.lower = max(self.lower, lower)
        if upper is not None:
            self.narrow(upper)
        if self.on_iteration is not None:
            self.on_iteration(self.lower, self.upper)


@dataclass(frozen=True, eq=False)
class _Problem:
    """One synthesize call's product, settings and time budget, shared by its phases."""

    tables: ProductTables
    settings: SynthesisSettings      # its suffix_length chosen (not None)
    progress: _Progress
    budget: TimeBudget
    roots_q: tuple[int, ...]         # the DFA states position 0 can be read as
    shortest: int                    # junctions to acceptance in the road x DFA graph, at least

    @property
    def tau(self) -> float:
        return self.settings.tau

    @property
    def belief_rule(self) -> BeliefRule:
        return self.settings.belief_rule

    @property
    def suffix_length(self) -> int:
        assert self.settings.suffix_length is not None
        return self.settings.suffix_length

    def search(self, horizon: int | None, tau: float, suffix_length: int, until: float,
               value: np.ndarray | None = None, abstraction: Abstraction | None = None
               ) -> tuple[PolicyTable, SearchRun]:
        return bounded_search(self.tables, replace(self.settings, tau=tau, suffix_length=suffix_length),
                              horizon, self.budget.ending(until), value, abstraction,
                              on_iteration=self.round_of(horizon))

    def round_of(self, horizon: int | None) -> Callable[[float, float], None]:
        """The progress of one search's rounds: its U is told only when it bounds the problem asked."""
        asked = horizon == self.settings.horizon
        return lambda lower, upper: self.progress.report(lower, upper if asked else None)

    def report(self, lower: float, upper: float) -> None:
        self.progress.report(lower, upper)


@dataclass(frozen=True, eq=False)
class _Answer:
    """A phase's answer: its bounds, the policy table of its L, that policy's strict-label value,
    its runs, and (unbounded) how U was obtained."""

    lower: float
    upper: float
    table: PolicyTable | None
    strict: float
    runs: tuple[Run, ...]
    unbounded_upper: str | None = None
    ran_out: bool = False    # (unbounded) every step ran to its end, none cut by the clock


def cluster_order(tables: ProductTables, symbols: ObservationSymbols, horizon: int | None,
                   completion: str, clusters: str) -> str:
    """CLUSTER_MODES: "first" (cluster policies before the search), "after" (after a search that
    ends with a gap above tau; not in the "early" mode) or "never"."""
    if clusters == "off" or symbols.rule != "bayes":
        return "never"
    if clusters == "on":
        return "first"
    depth = horizon if horizon is not None else UNBOUNDED_DEPTH
    large = completion == "auto" and completion_tree_leaves(
        tables, symbols, state_only_task(tables.pomdp.town, tables.spec), depth) > AUTO_TREE_LEAVES
    if large:
        return "first"
    return "never" if clusters == "early" else "after"


def _cluster_table(solution: ClusterSolution, n_trust: int) -> PolicyTable:
    """A policy table of box rows only (the exact-belief rule then reads the boxes)."""
    return PolicyTable.empty(n_trust, boxes=solution.rows)


def _cluster_run(solution: ClusterSolution, upper: float, horizon: int,
                 tried: list[ClusterAttempt]) -> ClusterRun:
    """The run record of a cluster policy."""
    return ClusterRun(horizon=horizon, lower=solution.lower, upper=upper, cluster_cap=solution.cap,
                      clusters=solution.clusters, policy_rows=solution.rows.rows,
                      cluster_runs=tuple(tried), lower_strict_labels=solution.lower)


def _by_graph_distance(problem: _Problem, horizon: int | None, never: bool) -> _Answer:
    """No route accepts within H junctions, whatever the labels: L = U = 0 without search."""
    note = ("graph distance: acceptance is unreachable" if never else
            f"graph distance: acceptance needs at least {problem.shortest} junctions")
    table = PolicyTable.empty(problem.tables.pomdp.n_trust)
    run = GraphDistanceRun(horizon=horizon, abstraction_bound=note,
                           root_dfa_states=problem.roots_q)
    return _Answer(0.0, 0.0, table, 0.0, (run,),
                   "graph distance: acceptance is unreachable" if horizon is None else None)


def _bounded_clusters(problem: _Problem, symbols: ObservationSymbols, horizon: int, until: float,
                      runs: list[Run]) -> tuple[ClusterSolution | None, float]:
    """The best cluster policy for `horizon` by `until`, recorded in `runs`; and the smallest U."""
    found, found_upper, tried = best_cluster_solution(problem.tables, symbols, list(problem.roots_q),
                                                      horizon, problem.tau, until)
    if found is not None:
        runs.append(_cluster_run(found, found_upper, horizon, tried))
        problem.report(found.lower, found_upper)
    return found, found_upper


def _bounded(problem: _Problem, horizon: int) -> _Answer:
    """P(accepted within `horizon` junctions): the search, with cluster policies before or after
    it (CLUSTER_MODES); the better L with its policy and the smaller U."""
    tables, budget, tau = problem.tables, problem.budget, problem.tau
    n_trust = tables.pomdp.n_trust
    symbols = observation_symbols(tables.pomdp, problem.belief_rule)
    order = cluster_order(tables, symbols, horizon, problem.settings.completion, problem.settings.clusters)
    runs: list[Run] = []
    cluster, cluster_upper = None, 1.0
    if order == "first":
        cluster, cluster_upper = _bounded_clusters(problem, symbols, horizon,
                                                   budget.share(CLUSTER_SHARE), runs)
    if cluster is not None and cluster_upper - cluster.lower <= tau:
        return _Answer(cluster.lower, cluster_upper, _cluster_table(cluster, n_trust), cluster.lower,
                       tuple(runs))
    until = budget.share(SEARCH_SHARE) if order == "after" else budget.deadline
    table, run = problem.search(horizon, tau, problem.suffix_length, until)
    runs.append(run)
    lower, upper, strict = run.lower, run.upper, run.lower_strict_labels
    if order == "after" and upper - lower > tau and not budget.expired():
        cluster, cluster_upper = _bounded_clusters(problem, symbols, horizon, budget.deadline, runs)
    if cluster is not None:
        upper = min(upper, cluster_upper)
        if cluster.lower > lower:
            lower, table, strict = cluster.lower, _cluster_table(cluster, n_trust), cluster.lower
    return _Answer(lower, upper, table, strict, tuple(runs))


def _unbounded_clusters(problem: _Problem, symbols: ObservationSymbols, upper: float, lower: float,
                        until: float, runs: list[Run]) -> tuple[ClusterSolution | None, bool]:
    """Cluster policies for L (accepting within H junctions): growing horizons with the
    first cap (more junctions to come back to a waypoint usually lift L most), then larger
    caps at the best horizon; the one of the largest L above `lower`, if any, and whether a round
    or a cap was left out (by the clock, or by the memory a cap would take)."""
    budget, tau = problem.budget, problem.tau
    best: tuple[ClusterSolution, int] | None = None      # (solution, its depth)
    rounds: list[tuple[int, tuple[int, ...]]] = [(problem.shortest + slack, UNBOUNDED_CLUSTER_CAPS[:1])
                                                 for slack in UNBOUNDED_CLUSTER_SLACK]
    cut = False
    while rounds:
        depth, caps = rounds.pop(0)
        if upper - lower <= tau:
            break
        if budget.expired(until):
            cut = True
            break
        found, _, tried = best_cluster_solution(problem.tables, symbols, list(problem.roots_q), depth,
                                                tau, until, caps, enough=upper - tau)
        cut = cut or len(tried) < len(caps) or any(attempt.lower is None for attempt in tried)
        if found is None:
            break
        runs.append(_cluster_run(found, upper, depth, tried))
        problem.report(found.lower, upper)
        if found.lower > lower:
            best, lower = (found, depth), found.lower
        if not rounds and best is not None and len(caps) == 1:
            rounds.append((best[1], UNBOUNDED_CLUSTER_CAPS))
    return (None if best is None else best[0]), cut


@dataclass(frozen=True, eq=False)
class _UnboundedBound:
    """The unbounded abstraction (suffix length k) and its end-component bound, capped at 1."""

    k: int
    abstraction: Abstraction
    bound: UnboundedBound
    value: np.ndarray


def _unbounded_searches(problem: _Problem, symbols: ObservationSymbols, bound: _UnboundedBound,
                        best: _Answer, until: float, runs: list[Run]) -> _Answer:
    """Bounded searches with growing H for L (each uses the bounded abstraction of the automatic
    suffix length, capped by the unbounded bound when the cells are the same); after the first,
    the unbounded problem itself is searched for UNBOUNDED_SEARCH_SHARE of the time left (open
    nodes valued by the bound), which lowers U where the bound is loose."""
    budget, tau = problem.budget, problem.tau
    searched_unbounded = False
    for depth in UNBOUNDED_HORIZONS:
        if best.upper - best.lower <= tau or (runs and budget.expired(until)):
            break
        k_run = bounded_suffix_length(problem.tables, symbols.n_changing, problem.suffix_length, depth)
        shared = k_run == bound.k
        table, run = problem.search(depth, 0.5 * tau, k_run, until, bound.value if shared else None,
                                    bound.abstraction if shared else None)
        runs.append(run)
        best = _better(best, run, table)
        if not searched_unbounded and best.upper - best.lower > tau:
            searched_unbounded = True
            # a share of the search's time, or of the whole budget's once a bounded search has
            # overrun the search's share: a share of nothing would leave U at the bound's 1
            table, run = problem.search(None, tau, bound.k,
                                        budget.share_of_rest(UNBOUNDED_SEARCH_SHARE,
                                                             None if budget.expired(until) else until),
                                        bound.value, bound.abstraction)
            run = replace(run, end_component_seconds=bound.bound.seconds)
            runs.append(run)
            best = replace(_better(best, run, table), upper=min(best.upper, run.upper))
    return best


def _better(best: _Answer, run: Run, table: PolicyTable) -> _Answer:
    """`best` with the run's L, policy and strict value when its L is larger."""
    if run.lower > best.lower:
        return replace(best, lower=run.lower, table=table, strict=run.lower_strict_labels)
    return best


def _unbounded(problem: _Problem) -> _Answer:
    """The unbounded problem: U from the end-component bound (tightened by a search of the
    unbounded problem), L from bounded horizons and cluster policies (CLUSTER_MODES)."""
    tables, budget, tau = problem.tables, problem.budget, problem.tau
    symbols = observation_symbols(tables.pomdp, problem.belief_rule)
    k = unbounded_suffix_length(tables, symbols.n_changing, problem.suffix_length)
    abstraction = build_abstraction(tables, symbols, suffix_cells(symbols, k))
    bound = unbounded_bound(abstraction, budget.share(UNBOUNDED_BOUND_SHARE))
    note = (f"suffix length {k}: {bound.end_components} end components collapsed, "
            f"{bound.iterations} iterations from above and below (largest remaining gap "
            f"{bound.gap:.2e}; every iterate from above is sound)" if bound.complete else
            "end-component bound stopped by the time limit: 1 wherever acceptance is possible")
    value = np.minimum(bound.value, 1.0)
    upper = float(max(value[tables.start, q, 0] for q in problem.roots_q))
    problem.progress.narrow(upper)
    best = _Answer(-1.0, upper, None, 0.0, (), note)
    runs: list[Run] = []
    order = cluster_order(tables, symbols, None, problem.settings.completion, problem.settings.clusters)
    cut = not bound.complete
    if order == "first":
        found, clusters_cut = _unbounded_clusters(problem, symbols, upper, best.lower,
                                                  budget.share(CLUSTER_SHARE), runs)
        best, cut = _with_cluster(best, found, tables), cut or clusters_cut
    until = budget.share(SEARCH_SHARE) if order == "after" else budget.deadline
    best = _unbounded_searches(problem, symbols, _UnboundedBound(k, abstraction, bound, value), best,
                               until, runs)
    if order == "after" and best.upper - best.lower > tau:
        found, clusters_cut = ((None, True) if budget.expired() else
                               _unbounded_clusters(problem, symbols, best.upper, best.lower,
                                                   budget.deadline, runs))
        best, cut = _with_cluster(best, found, tables), cut or clusters_cut
    searches = [run for run in runs if isinstance(run, SearchRun)]
    ran_out = (not cut and not budget.expired()
               and {run.horizon for run in searches} >= {*UNBOUNDED_HORIZONS, None}
               and all(run.stopped != "deadline" for run in searches))
    return replace(best, lower=max(best.lower, 0.0), runs=tuple(runs), ran_out=ran_out)


def unbounded_schedule_note(seconds: float) -> str:
    """What a reader of an unbounded synthesis that ran its whole schedule unconverged ("depth
    cap", `seconds` it took) should know: more time would not move its bounds."""
    return (f"every step of the unbounded synthesis ran to its end (bounded searches up to "
            f"{UNBOUNDED_HORIZONS[-1]} junctions, the unbounded search to depth {UNBOUNDED_DEPTH} with "
            f"the end-component bound beyond, the cluster policies' rounds) after {seconds:.1f} s, "
            "before its time limit: a longer --time-limit would not tighten these bounds")


def _with_cluster(best: _Answer, found: ClusterSolution | None, tables: ProductTables) -> _Answer:
    """`best` with a cluster policy's L and table, when one was found (it beats best's L)."""
    if found is None:
        return best
    return replace(best, lower=found.lower, table=_cluster_table(found, tables.pomdp.n_trust),
                   strict=found.lower)


def rounding_depth(runs: tuple[Run, ...], horizon: int | None) -> int:
    """The most observation steps a history has in any computation behind the bounds: the
    horizon, or (unbounded) the deepest run's (a search of the unbounded problem leaves nodes
    UNBOUNDED_DEPTH deep open, valued by the end-component bound, itself rounded up per sweep)."""
    if horizon is not None:
        return horizon
    return max((UNBOUNDED_DEPTH if run.horizon is None else run.horizon for run in runs), default=0)


def _root_dfa_states(tables: ProductTables) -> tuple[int, ...]:
    """The DFA state position 0 is read as, its belief labels decided exactly on the prior
    (policies/belief/exact_labels.py)."""
    return (tables.initial_q,)


def synthesize(pomdp: TrustPOMDP, spec: Spec, settings: SynthesisSettings = DEFAULT_SYNTHESIS,
               on_iteration: Callable[[float, float], None] | None = None) -> BeliefSynthesis:
    """Maximal probability of satisfying `spec` from (spec.start, initial belief), with a policy.

    settings (policies/synthesis/settings.py):
    horizon: at most this many junctions (None: unbounded). belief_rule: the AV's filter and the
    belief MDP's dynamics ("bayes", or the authors' "paper" update with observation probabilities
    b·P(o|θ) of that belief). Returns lower <= Pr_max <= upper with lower a lower bound of the value of
    the returned policy; stops when upper - lower <= tau or after about time_limit seconds.

    Unbounded: lower is the best P(accepted within H junctions) of bounded searches with growing H
    (UNBOUNDED_HORIZONS): a policy accepting within H with probability L satisfies the unbounded spec
    with probability >= L. upper is the unbounded abstraction's bound, tightened by a search of the
    unbounded problem when a gap remains. on_iteration(lower, upper): called after every expansion
    round with the current search's root bounds (progress bars). compress: "chains" passes through
    quiet roads without a choice, "full" searches the event graph's macro moves
    (policies/synthesis/event_graph.py), "off" goes junction by junction; the same bounds at
    convergence (docs/synthesis.md, "The event graph"). completion: how open nodes are valued
    (COMPLETION_MODES; "auto": exact trees, so that lower is the policy's exact value, where the
    trust-free route's observation tree fits AUTO_TREE_LEAVES, cluster bounds otherwise;
    docs/synthesis.md, "Open nodes and the acting rule"). clusters: whether cluster policies
    (policies/synthesis/cluster_policy.py) are solved before the search (CLUSTER_MODES); the better
    certified L of the two is returned, and the smaller U. work_limit: the whole call's units of
    work (policies/work_clock.py): every schedule below then reads the work done, not the time.
    """
    with work_clock(settings.work_limit, settings.time_limit) as limit:
        return _synthesize(pomdp, spec, replace(settings, time_limit=limit), on_iteration)


def _synthesize(pomdp: TrustPOMDP, spec: Spec, settings: SynthesisSettings,
                on_iteration: Callable[[float, float], None] | None) -> BeliefSynthesis:
    """`synthesize` on the clock installed for it."""
    tau, horizon, belief_rule = settings.tau, settings.horizon, settings.belief_rule
    # The last few per cent are kept for the work after the deadline check (final backup, the
    # policy table, the stats), so that the whole call ends within the limit.
    budget = TimeBudget.start(settings.time_limit, reserve=FINISH_SHARE)
    tables = build_product(pomdp, spec)
    suffix_length = settings.suffix_length
    if suffix_length is None:
        n_changing = observation_symbols(pomdp, belief_rule).n_changing
        suffix_length = automatic_suffix_length(n_changing)
        if horizon is not None:
            suffix_length = bounded_suffix_length(tables, n_changing, suffix_length, horizon)
    distance = acceptance_distance(tables)
    roots_q = _root_dfa_states(tables)
    shortest = int(min(distance[tables.start, q] for q in roots_q))
    problem = _Problem(tables, replace(settings, suffix_length=suffix_length), _Progress(on_iteration),
                       budget, roots_q, shortest)
    never = shortest > tables.n_x * tables.n_q      # unreachable in the road x DFA graph
    if never or (horizon is not None and shortest > horizon):
        answer = _by_graph_distance(problem, horizon, never)
    elif horizon is not None:
        answer = _bounded(problem, horizon)
    else:
        answer = _unbounded(problem)
    table = answer.table
    if table is None:
        raise AttributeError("the synthesis ended without a policy table")
    # Convergence is decided on the bounds as computed (a search that closed its gap exactly has
    # closed it); what is reported is rounded outward, so that it holds exactly (rounding.py).
    converged = bool(answer.upper - answer.lower <= tau)
    margin = relative_margin(model_rounding(pomdp, belief_rule), rounding_depth(answer.runs, horizon),
                             belief_rule)
    lower, upper = widen(answer.lower, answer.upper, margin)
    policy = BeliefTablePolicy(table, pomdp.town, spec, lower=lower, upper=upper, horizon=horizon)
    stats = SynthesisStats(
        belief_rule=belief_rule, converged=converged, tau=tau, runs=answer.runs,
        policy_rows=table.rows, lower_strict_labels=max(float(rounded_down(answer.strict, margin)), lower),
        unbounded_upper=answer.unbounded_upper,
        lower_from_horizon=(max(answer.runs, key=lambda r: r.lower).horizon
                            if horizon is None else None),
        stopped="depth cap" if answer.ran_out and not converged else None)
    return SynthesisResult(policy=policy, lower=lower, upper=upper, seconds=budget.elapsed(),
                           stats=stats, horizon=horizon, belief_rule=belief_rule)
