"""Synthesis for specs with trust-state atoms: a policy on the joint belief, with L <= Pr_max <= U.

`synthesize_spec` (policies/synthesize_spec.py) hands specs whose formula tests the hidden trust here
(docs/trust_states.md, "Synthesis with trust-state atoms"). The method:

* Search. `joint_search` unfolds the belief tree over (road, J(θ, q)) to depth D, every action and
  observation, merging bit-identical nodes and keeping at most N nodes per level (the likeliest;
  the others are cut leaves valued by the open-loop continuation below and the θ,q-observing
  relaxation above). Bounded horizon H: D = H. Unbounded: the upper bound comes from unbounded
  searches (depths UNBOUNDED_DEPTHS, leaves valued by the relaxation's unbounded values), the
  policy from bounded searches with H in UNBOUNDED_POLICY_HORIZONS.
* The policy (policies/routing/trust_state_table.py) takes the search's lower-greedy action at every
  expanded node (matched on (t, x, J, b)) and the relaxation's greedy action elsewhere. The
  search expands the GUIDED_FACTOR × N nodes of a level ranked after its N expanded ones with
  that very greedy action (joint_search's guided nodes), so the lower bound it backs up, and the
  decisions it takes by it, are that policy's value but at the nodes beyond both caps.
* L is the returned policy's own value within its search horizon H, computed by the merged exact
  unfolding `evaluate_joint_table` (policies/evaluation/trust_state.py; tests check it against
  `evaluate_joint` and brute force), its certified lower end when the least likely nodes are
  dropped. A policy accepting within H junctions with probability L satisfies the spec (bounded
  by any H' >= H) with probability >= L. Unbounded objective: L is the policy's value over
  unbounded time, its merged unfolding continued past H (`evaluate_joint_table_unbounded`: value
  iteration from below on the policy's chain of beliefs) until the live mass left is at most
  1e-9 or the round's deadline, each level a sound lower bound. U is the smallest search upper bound (each
  sound for Pr_max). So L <= value(policy) <= Pr_max <= U.
* Rounds: N starts at FIRST_NODES and grows by NODE_GROWTH while upper - lower > tau, some node
  was cut, and the next round (predicted NODE_GROWTH times the last) fits the time left. Each
  search and evaluation checks the deadline level by level (a search expands for joint_search.EXPAND_SHARE of
  its time and values leaves in the rest; an evaluation does not begin a batch or a merge it
  predicts would end late), so even the first round keeps to the time limit; what is cut short
  leaves sound bounds (unexpanded nodes are leaves, unevaluated mass is unknown).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, TypeAlias

import numpy as np

from trustroute.policies.belief.trust_state_relaxation import RELAXATION_MARGIN, RelaxedGuide, relaxed_guide
from trustroute.policies.evaluation.trust_state import (
    UNBOUNDED_MAX_LEVELS,
    evaluate_joint_table,
    evaluate_joint_table_unbounded,
)
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.routing.protocol import Certificate
from trustroute.policies.routing.trust_state_table import JointPolicyTable, JointTablePolicy
from trustroute.policies.synthesis.budget import TimeBudget
from trustroute.policies.synthesis.result import Record, RoundProgress, SynthesisResult, record_dict
from trustroute.policies.synthesis.rounding import joint_rounding, relative_margin, rounded_down, rounded_up
from trustroute.policies.synthesis.settings import DEFAULT_SYNTHESIS, SynthesisSettings
from trustroute.policies.trust_state_synthesis.search import (
    JointBounds,
    JointDecisions,
    JointLimits,
    joint_search,
)
from trustroute.policies.work_clock import work_clock

FIRST_NODES = 500                  # nodes per level of the first round
NODE_GROWTH = 4                    # nodes per level grow by this factor per round
MAX_NODES = 512_000
GUIDED_FACTOR = 4                  # nodes per level that follow the guide, per fully expanded node
UNBOUNDED_POLICY_HORIZONS = (20, 30)
EVALUATION_NODES = 50_000          # frontier cap of the policy's evaluation (pruned mass: unknown)
UNBOUNDED_DEPTHS = (10, 20)        # depths of the unbounded searches (upper bound)
UPPER_SHARE = 0.25                 # unbounded: share of the time limit for the upper bound
FINISH_RESERVE = 0.01             # share of the time limit kept for what follows the last check
SEARCH_SHARE = 0.6                 # share of a round's time left for its search (the rest: evaluation)


@dataclass(frozen=True)
class PolicyValue:
    """The returned policy's certified [lower, upper] and what ended its evaluation (`stopped`,
    policies/evaluation/ledgers.py UNFOLDING_STOPS); unbounded objective: how many junctions it
    unfolded and `stopped_by`, that end as the one rule names it (work_clock.stopped_by, read on
    the clock of the synthesis as the evaluation ended)."""

    lower: float
    upper: float
    stopped: str
    junctions: int | None = None
    stopped_by: str | None = None


@dataclass(frozen=True, kw_only=True)
class JointRun(Record):
    """One search round: which search (its depth or policy horizon), the nodes per level it
    kept, its bounds, and (policy rounds) the certified value of the policy it gave."""

    search: str
    max_nodes: int
    bounds: JointBounds
    policy: PolicyValue | None = None

    def to_dict(self) -> dict:
        out = {"search": self.search, "max_nodes": self.max_nodes, **self.bounds.to_dict()}
        if self.policy is not None:
            out.update({"policy_lower": self.policy.lower, "policy_upper": self.policy.upper})
        return out


# What ended a trust-state synthesis (JointSynthesisStats.stopped): "convergence" (the gap reached
# tau), "deadline" (a phase's rounds, or the returned policy's evaluation, ran out of the time or
# work limit's share: more could tighten the bounds) or the cap that left the gap before any limit
# (work_clock.CAPS): "node cap" (the policy's evaluation dropped nodes beyond EVALUATION_NODES, or
# the search's rounds reached MAX_NODES per level), "junction cap" (the unbounded evaluation reached
# UNBOUNDED_MAX_LEVELS), "depth cap" (unbounded: every search complete at its fixed depth,
# UNBOUNDED_DEPTHS and UNBOUNDED_POLICY_HORIZONS, the gap what those depths leave) or "rounding
# margin" (within a horizon: the search complete and the policy's value exact, the gap is the
# search's allowance for floating-point rounding, RELAXATION_MARGIN, and tau is below it).
JOINT_STOPS = ("convergence", "deadline", "node cap", "junction cap", "depth cap", "rounding margin")


@dataclass(frozen=True, kw_only=True)
class JointSynthesisStats:
    """How a trust-state synthesis obtained its bounds: its rounds, the returned policy's search
    horizon, that search's own lower bound, the policy's certified value within it, and what
    ended it (`stopped`, JOINT_STOPS)."""

    method: str = "search over joint (trust, DFA state) beliefs (policies/trust_state_synthesis)"
    belief_rule: str
    converged: bool
    stopped: str
    tau: float
    runs: tuple[JointRun, ...]
    policy_rows: int
    policy_search_horizon: int
    search_lower: float
    policy_value: PolicyValue

    def to_dict(self) -> dict:
        value = self.policy_value
        policy_value: dict[str, object]
        if value.stopped_by is None:
            policy_value = {"lower": value.lower, "upper": value.upper,
                            "max_junctions": self.policy_search_horizon}
        else:
            policy_value = {"lower": value.lower, "upper": value.upper, "unbounded": True,
                            "junctions_unfolded": value.junctions, "stopped_by": value.stopped_by}
        return {**record_dict(self), "policy_value": policy_value}


def joint_cap_note(cap: str, seconds: float) -> str:
    """What a reader of a trust-state synthesis' bounds should know of the cap that ended it
    (JOINT_STOPS; `seconds` it took): which cap, and that more time would not move the bounds."""
    depths = " and ".join(map(str, UNBOUNDED_DEPTHS))
    horizons = " and ".join(map(str, UNBOUNDED_POLICY_HORIZONS))
    what = {
        "node cap": f"the search reached {MAX_NODES:,} nodes per level, or the policy's evaluation "
                    f"dropped nodes beyond {EVALUATION_NODES:,} per level (their live mass unknown),",
        "junction cap": "the policy's evaluation over unbounded time stopped at "
                        f"{UNBOUNDED_MAX_LEVELS:,} junctions with live mass still open,",
        "depth cap": f"every search was complete at its fixed depth ({depths} junctions for the upper "
                     f"bound, policy horizons {horizons}),",
        "rounding margin": "the bounds are exact but for the search's allowance for rounding "
                           f"({RELAXATION_MARGIN:g}), which is above tau,",
    }[cap]
    return (f"{what} after {seconds:.1f} s, before its time limit: a longer --time-limit would not "
            "tighten these bounds")


def joint_margin(pomdp: TrustPOMDP, spec: Spec, belief_rule: BeliefRule, depth: int) -> float:
    """The relative margin (rounding.py) of the joint (θ, q) filter's histories of at most `depth`
    junctions under `belief_rule`: what a trust-state synthesis' L and U, and a value of its policy
    reported beside them, are rounded outward by."""
    rounding = joint_rounding(pomdp, compile_spec(spec, pomdp.town).dfa.n_states, belief_rule)
    return relative_margin(rounding, depth, belief_rule)


JointSynthesis: TypeAlias = SynthesisResult[JointTablePolicy, JointSynthesisStats]


@dataclass(frozen=True, eq=False)
class _Candidate:
    policy: JointTablePolicy
    value: PolicyValue
    bounds: JointBounds
    horizon: int


def decision_table(decisions: JointDecisions) -> JointPolicyTable:
    """The rows of a JointTablePolicy from the search's decisions (the DFA state told: the most
    probable under J)."""
    told = np.argmax(decisions.joint.sum(axis=1), axis=1) if decisions.joint.size else \
        np.zeros(0, dtype=np.int64)
    return JointPolicyTable(t=decisions.t, x=decisions.x, q=told, beliefs=decisions.beliefs,
                            joint=decisions.joint, action=decisions.action)


def _grow(run: Callable[[int, float], Any], stop: Callable[[Any], bool], deadline: float) -> str:
    """run(nodes, deadline) with nodes per level growing from FIRST_NODES until stop(result)
    ("done"), the next round (predicted NODE_GROWTH times the last) would pass the deadline
    ("deadline") or its nodes per level MAX_NODES ("node cap"); returns which. The first round
    always starts; `run` itself stops at the deadline (the searches and the evaluation check it
    level by level), so even the first round keeps to it."""
    nodes = FIRST_NODES
    budget = TimeBudget.until(deadline)
    while True:
        began = budget.used()
        result = run(nodes, deadline)
        if stop(result):
            return "done"
        if not budget.fits(NODE_GROWTH * (budget.used() - began)):
            return "deadline"
        nodes *= NODE_GROWTH
        if nodes > MAX_NODES:
            return "node cap"


@dataclass(frozen=True, eq=False)
class _Joint:
    """One synthesize_joint call's problem and settings, shared by its rounds."""

    pomdp: TrustPOMDP
    spec: Spec
    horizon: int | None
    belief_rule: BeliefRule
    tau: float


def _unbounded_upper(problem: _Joint, deadline: float, log: list[JointRun],
                     report: Callable[[float], None], ends: list[str]) -> float:
    """Upper bound of the unbounded objective: unbounded searches (UNBOUNDED_DEPTHS), leaves
    valued by the relaxation, with growing nodes per level until the deadline; what ended each
    depth's rounds appended to `ends` (`_grow`)."""
    upper = 1.0
    for depth in UNBOUNDED_DEPTHS:
        def run_upper(nodes: int, deadline: float, depth: int = depth) -> JointBounds:
            nonlocal upper
            bounds, _ = joint_search(problem.pomdp, problem.spec, depth, None, problem.belief_rule,
                                     JointLimits(max_nodes=nodes, deadline=deadline))
            upper = min(upper, bounds.upper)
            log.append(JointRun(search=f"unbounded depth {depth}", max_nodes=nodes, bounds=bounds))
            report(upper)
            return bounds

        ends.append(_grow(run_upper, lambda bounds: bounds.cut_nodes == 0, deadline))
    return upper


def _policy_value(problem: _Joint, policy: JointTablePolicy, policy_horizon: int,
                  deadline: float) -> PolicyValue:
    """The policy's certified value: within the horizon for a bounded objective; over unbounded
    time for the unbounded one (its chain of beliefs unfolded past `policy_horizon` until the
    live mass left is negligible or the deadline)."""
    if problem.horizon is not None:
        within = evaluate_joint_table(problem.pomdp, problem.spec, policy, policy_horizon,
                                      problem.belief_rule, EVALUATION_NODES, deadline=deadline)
        return PolicyValue(within.lower, within.upper, within.stopped)
    value = evaluate_joint_table_unbounded(problem.pomdp, problem.spec, policy, problem.belief_rule,
                                           EVALUATION_NODES, deadline=deadline)
    return PolicyValue(value.lower, value.upper, value.stopped, value.junctions, value.stopped_by())


def _policy_rounds(problem: _Joint, policy_horizon: int, until: float, upper: float,
                   best: list[_Candidate], guides: dict[int, RelaxedGuide], log: list[JointRun],
                   report: Callable[[float], None]) -> tuple[float, str]:
    """Policies for `policy_horizon` junctions with growing nodes per level until `until`, each
    valued exactly within that horizon (a lower bound for any longer H and for the unbounded
    objective); the best kept in `best`. Returns the upper bound (lowered by bounded searches)
    and what ended the rounds (`_grow`)."""
    pomdp, spec, horizon = problem.pomdp, problem.spec, problem.horizon

    def run_policy(nodes: int, deadline: float) -> bool:
        nonlocal upper
        guide = guides.get(policy_horizon) or guides.setdefault(
            policy_horizon, relaxed_guide(pomdp, spec, policy_horizon))
        search_deadline = TimeBudget.until(deadline).share_of_rest(SEARCH_SHARE)
        limits = JointLimits(max_nodes=nodes, guided_nodes=GUIDED_FACTOR * nodes, deadline=search_deadline)
        bounds, decisions = joint_search(pomdp, spec, policy_horizon, policy_horizon, problem.belief_rule,
                                         limits, guide=guide)
        if horizon is not None:
            upper = min(upper, bounds.upper)
        policy = JointTablePolicy(decision_table(decisions), pomdp, spec, guide_horizon=policy_horizon,
                                  certificate=Certificate(horizon=horizon), guide=guide)
        value = _policy_value(problem, policy, policy_horizon, deadline)
        log.append(JointRun(search=f"H={policy_horizon}", max_nodes=nodes, bounds=bounds, policy=value))
        if not best or value.lower > best[0].value.lower:
            best[:] = [_Candidate(policy, value, bounds, policy_horizon)]
        report(upper)
        return upper - best[0].value.lower <= problem.tau or bounds.cut_nodes == 0

    ended = _grow(run_policy, lambda done: done, until)   # (it lowers `upper`)
    return upper, ended


def _stopped(converged: bool, ends: list[str], value: PolicyValue, horizon: int | None) -> str:
    """What ended a synthesis (JOINT_STOPS) from what ended each phase's rounds (`ends`) and the
    returned policy's evaluation (`value`): a cap only when no phase ran out of time first."""
    if converged:
        return "convergence"
    if "deadline" in ends or value.stopped == "deadline":
        return "deadline"
    if value.stopped != "convergence":
        return value.stopped                 # the evaluation's node or junction cap
    if "node cap" in ends:
        return "node cap"
    # every search complete ("done"): unbounded, at its fixed depth; within a horizon it is exact,
    # and so is the policy's value, so the gap is the search's allowance for rounding
    return "depth cap" if horizon is None else "rounding margin"


def synthesize_joint(pomdp: TrustPOMDP, spec: Spec, settings: SynthesisSettings = DEFAULT_SYNTHESIS,
                     on_iteration: RoundProgress | None = None) -> JointSynthesis:
    """A JointTablePolicy for `spec` and certified lower <= Pr_max <= upper (a SynthesisResult);
    of `settings`, tau, time_limit, work_limit, horizon and belief_rule apply (the others are the
    belief-MDP search's)."""
    with work_clock(settings.work_limit, settings.time_limit) as limit:
        return _synthesize_joint(pomdp, spec, replace(settings, time_limit=limit), on_iteration)


def _synthesize_joint(pomdp: TrustPOMDP, spec: Spec, settings: SynthesisSettings,
                      on_iteration: RoundProgress | None) -> JointSynthesis:
    """`synthesize_joint` on the clock installed for it."""
    tau, time_limit, horizon = settings.tau, settings.time_limit, settings.horizon
    belief_rule = settings.belief_rule
    # Every search and evaluation checks its deadline as it goes (and does not begin a batch it
    # predicts would end past it), so the whole synthesis keeps to the time limit.
    budget = TimeBudget.start(time_limit, reserve=FINISH_RESERVE)
    compile_spec(spec, pomdp.town)       # bad specs fail before any search
    problem = _Joint(pomdp, spec, horizon, belief_rule, tau)
    log: list[JointRun] = []
    best: list[_Candidate] = []

    def report(upper: float) -> None:
        if on_iteration is not None:
            on_iteration(best[0].value.lower if best else None, upper)   # L: a valued policy's

    upper = 1.0
    ends: list[str] = []    # what ended each phase's rounds (`_grow`)
    if horizon is None:
        upper = _unbounded_upper(problem, budget.share(UPPER_SHARE), log, report, ends)
    horizons = (horizon,) if horizon is not None else UNBOUNDED_POLICY_HORIZONS
    guides: dict[int, RelaxedGuide] = {}
    for k, policy_horizon in enumerate(horizons):
        until = budget.share_of_rest(1.0 / (len(horizons) - k))
        upper, ended = _policy_rounds(problem, policy_horizon, until, upper, best, guides, log, report)
        ends.append(ended)
        if upper - best[0].value.lower <= tau:
            break
    chosen = best[0]
    policy, value = chosen.policy, chosen.value
    # converged on the computed values; L reported rounded down for the joint filter's histories
    # of at most the policy's evaluation cap, U up for the searches' depth (rounding.py: the
    # relaxation's per-backup margin covers its own sums, not the float model against the exact
    # one, such as a candidate's type prior that sums to 1 only within its tolerance)
    converged = bool(upper - value.lower <= tau)
    depth = chosen.horizon if value.junctions is None else max(value.junctions, chosen.horizon)
    lower = float(rounded_down(value.lower, joint_margin(pomdp, spec, belief_rule, depth)))
    upper_depth = horizon if horizon is not None else max(UNBOUNDED_DEPTHS)
    upper = float(rounded_up(upper, joint_margin(pomdp, spec, belief_rule, upper_depth)))
    policy.lower, policy.upper = lower, upper
    stats = JointSynthesisStats(
        belief_rule=belief_rule, converged=converged, stopped=_stopped(converged, ends, value, horizon),
        tau=tau, runs=tuple(log),
        policy_rows=policy.table.rows, policy_search_horizon=chosen.horizon,
        search_lower=chosen.bounds.lower, policy_value=value)
    return SynthesisResult(policy=policy, lower=lower, upper=upper, seconds=budget.elapsed(),
                           stats=stats, horizon=horizon, belief_rule=belief_rule)
