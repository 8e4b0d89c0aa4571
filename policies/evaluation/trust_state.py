"""Exact evaluation of a routing policy for specs that test the hidden trust (docs/trust_states.md).

The same tree unfolding as policies/evaluation/plain.py (one level per junction, one node per history of
observations, decisions asked once per distinct (route, DFA state told, AV belief)), with the
exact joint belief J(θ, q) of policies/belief/trust_state_filter.py at every node instead of one DFA
state. The spec is satisfied on a branch with probability J(accepting) when the branch ends;
accepting states are absorbing, so that mass only grows along a branch and is counted once, at
its end. A branch ends when its live mass (q neither accepting nor rejecting) is 0 (settled),
when the policy declares it finished, at the junction cap, or when it is pruned; the live mass
of a finished or capped branch is unsatisfied, that of a pruned branch unknown (the width of
[lower, upper]).

The AV does not know q: the policy is told the most probable DFA state (the exact one when the
spec has no trust-state atoms). Specs without trust-state atoms are evaluated by
policies/evaluation/plain.py itself, so their results are exactly today's.
"""

from __future__ import annotations

import time

import numpy as np

from trustroute.policies.belief.trust_state_filter import distinct_nodes, joint_filter
from trustroute.policies.evaluation.plain import (
    DEFAULT_MAX_NODES,
    DEFAULT_PRUNE_BELOW,
    Evaluation,
    accepted_bounds,
    decide_node,
    evaluate,
    extend_routes,
)
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.routing.episode_rules import DEFAULT_JUNCTION_CAP
from trustroute.policies.routing.fallback import DEFAULT_FALLBACK_AFTER, FallbackPolicy, with_fallback
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

# Defaults for specs with trust-state atoms (docs/trust_states.md, "Bounded evaluation"): the
# unfolding keeps the JOINT_MAX_NODES likeliest nodes of each level, which bounds its cost by
# about cap x 4 x JOINT_MAX_NODES node updates (the default cap in a few seconds on phi1_trust);
# histories below JOINT_PRUNE_BELOW are dropped as in policies.evaluation.plain.
JOINT_MAX_NODES = 5_000
JOINT_PRUNE_BELOW = DEFAULT_PRUNE_BELOW


def evaluate_joint(pomdp: TrustPOMDP, spec: Spec, policy: RoutingPolicy,
                   fallback_after: int | None = DEFAULT_FALLBACK_AFTER,
                   max_junctions: int = DEFAULT_JUNCTION_CAP,
                   belief_rule: BeliefRule = "bayes", prune_below: float | None = None,
                   max_nodes: int | None = None, force_joint: bool = False,
                   truth: TrustPOMDP | None = None,
                   reference: tuple[TrustPOMDP, Spec] | None = None,
                   merge: bool = True, time_limit: float | None = None) -> Evaluation:
    """Certified P(spec satisfied) of `policy`, for any mix of road, belief and trust-state atoms.

    Arguments as policies.evaluation.plain.evaluate. `force_joint` runs the joint unfolding even when the
    spec has no trust-state atoms (tests compare it with evaluate there). A true driver other than
    the AV's model (`truth`) or a second reading (`reference`) is evaluated for specs without
    trust-state atoms only. `merge` (default) merges, level by level, the histories that reach the
    same road and beliefs on routes the policy reads alike (`RoutingPolicy.route_memory`): the same
    value as the tree unfolding (`merge=False`, which tests compare), on far fewer nodes.

    Pruning (the unfolding is exponential in the cap: distinct histories almost never reach equal
    beliefs): a branch whose live mass is below `prune_below`, a node beyond the `max_nodes` of
    its level with the most live mass,
    and every branch still open `time_limit` seconds after the start are not followed; their
    accepted mass counts, their live mass is unknown (end_mass["pruned"] = upper - lower). The
    defaults are policies.evaluation.plain's for specs without trust-state atoms (which go there unchanged)
    and JOINT_PRUNE_BELOW, JOINT_MAX_NODES (no time limit) otherwise; `pruning` reports them and
    what they cut."""
    if not spec.uses_trust_atoms and not force_joint:
        if time_limit is not None:
            raise ValueError("a time limit applies to specs with trust-state atoms only")
        return evaluate(pomdp, spec, policy, fallback_after, max_junctions, belief_rule,
                        DEFAULT_PRUNE_BELOW if prune_below is None else prune_below,
                        DEFAULT_MAX_NODES if max_nodes is None else max_nodes,
                        truth=truth, reference=reference)
    if truth is not None or reference is not None:
        raise ValueError("a separate true driver or reference reading is not evaluated for specs with "
                         "trust-state atoms")
    started = time.perf_counter()
    prune_below = JOINT_PRUNE_BELOW if prune_below is None else prune_below
    max_nodes = JOINT_MAX_NODES if max_nodes is None else max_nodes
    deadline = None if time_limit is None else started + time_limit
    cut = {"below_threshold": 0.0, "beyond_budget": 0.0, "past_deadline": 0.0}
    cut_nodes = {"below_threshold": 0, "beyond_budget": 0, "past_deadline": 0}
    first_cut_level: int | None = None
    town, driver = pomdp.town, pomdp.driver
    if fallback_after is not None and not isinstance(policy, FallbackPolicy):
        policy = with_fallback(policy, town, spec, after=fallback_after)
    fallback_level = policy.after if isinstance(policy, FallbackPolicy) else None
    # A policy that decides batches of nodes at once (JointTablePolicy.prefetch) is given each
    # level's nodes in one call before the episode rules ask it node by node.
    batched = getattr(policy.inner if isinstance(policy, FallbackPolicy) else policy, "prefetch", None)
    batched = None if batched is None else batched.__self__
    compiled = compile_spec(spec, town)
    filter_ = joint_filter(pomdp, compiled.dfa, compiled.labeller)
    accepting = np.asarray(compiled.dfa.accepting, dtype=bool)
    levels = np.asarray(driver.trust_levels, dtype=float)
    outcomes = [(h, e) for h in (0, 1) for e in ((0, 1) if driver.depends_on_performance else (0,))]
    successor_index = {(x, j): town.state_index(town.successor(road, j))
                       for x, road in enumerate(town.states) for j in town.actions(road)}

    start = town.state_index(spec.start)
    routes: list[tuple[str, ...]] = [(spec.start,)]
    route_id = np.zeros(1, dtype=np.int64)
    road = np.array([start], dtype=np.int64)
    belief_av = np.asarray(pomdp.initial_belief, dtype=float)[None, :].copy()
    posterior = belief_av.copy()
    joint = filter_.initial(start, belief_av[0])
    probability = np.ones(1)
    memory_ids: dict = {}

    mass = {"accepted": 0.0, "rejected": 0.0, "destination": 0.0, "cap": 0.0, "pruned": 0.0,
            "settled": 0.0}
    trust_sum = 0.0
    junction_sum = 0.0
    ended_mass = 0.0
    fallback_mass = 0.0
    nodes = 1
    max_frontier = 1

    def end(mask: np.ndarray, reason: str, level: int, why: str = "") -> None:
        """Branches ending here: accepted and rejected mass by J, the live rest by `reason` (for
        "pruned", `why` names the cut)."""
        nonlocal trust_sum, junction_sum, ended_mass, first_cut_level
        p = probability[mask]
        accepted, rejected, live = filter_.masses(joint[mask])
        mass["accepted"] += float(p @ accepted)
        mass["rejected"] += float(p @ rejected)
        mass[reason] += float(p @ live)
        if reason == "pruned" and p.size:
            cut[why] += float(p @ live)
            cut_nodes[why] += int(p.size)
            first_cut_level = level if first_cut_level is None else first_cut_level
        if reason != "pruned":
            ended_mass += float(p.sum())
            trust_sum += float(p @ (posterior[mask] @ levels))
            junction_sum += float(p.sum()) * level

    for level in range(max_junctions + 1):
        _, _, live = filter_.masses(joint)
        settled = live <= 0
        end(settled, "settled", level)
        alive = ~settled
        if deadline is not None and level > 0 and time.perf_counter() > deadline:
            end(alive, "pruned", level, "past_deadline")
            break
        # What pruning a node costs is its live mass (its accepted mass is counted anyway).
        tiny = alive & (probability * live < prune_below)
        end(tiny, "pruned", level, "below_threshold")
        alive &= ~tiny
        if not alive.any():
            break
        keep = np.flatnonzero(alive)
        told_q = filter_.likeliest_q(joint[keep])
        told_accepting = accepting[told_q]
        if batched is not None:
            batched.prefetch(level, road[keep], joint[keep], belief_av[keep])

        finished = np.zeros(keep.size, dtype=bool)
        fired = np.zeros(keep.size, dtype=bool)
        chosen = np.full(keep.size, -1, dtype=np.int64)
        decisions: dict[tuple[int, int, bytes, bytes], tuple[bool, bool, int]] = {}
        # A policy whose decision on a route is the same for every belief and non-accepting DFA
        # state (route_determined: the fallback phase, the trust-free route) is asked once per
        # route told a non-accepting state (an accepting one may switch the fallback off); None
        # marks routes it is not so on.
        by_route: dict[int, tuple[bool, bool, int] | None] = {}
        for k, i in enumerate(keep.tolist()):
            rid = int(route_id[i])
            decision = None if told_accepting[k] else by_route.get(rid, ())
            if decision == ():
                context = DecisionContext(route=routes[rid], dfa_state=int(told_q[k]),
                                          belief=belief_av[i], joint=joint[i])
                decision = (decide_node(policy, context, town, int(road[i]), level, max_junctions,
                                        fallback_level, successor_index)
                            if policy.route_determined(context) else None)
                by_route[rid] = decision
            if decision is None:
                key = (rid, int(told_q[k]), belief_av[i].tobytes(), joint[i].tobytes())
                decision = decisions.get(key)
                if decision is None:
                    context = DecisionContext(route=routes[key[0]], dfa_state=key[1],
                                              belief=belief_av[i], joint=joint[i])
                    decision = decide_node(policy, context, town, int(road[i]), level, max_junctions,
                                           fallback_level, successor_index)
                    decisions[key] = decision
            finished[k], fired[k], chosen[k] = decision
        finished_mask = np.zeros(probability.size, dtype=bool)
        finished_mask[keep[finished]] = True
        end(finished_mask, "destination", level)
        if level == max_junctions:
            capped = np.zeros(probability.size, dtype=bool)
            capped[keep[~finished]] = True
            end(capped, "cap", level)
            break
        fallback_mass += float(probability[keep[fired]].sum())
        keep, chosen = keep[~finished], chosen[~finished]
        if keep.size == 0:
            break

        new_route_ids = extend_routes(routes, route_id[keep], chosen, town.states)

        incident = pomdp.road_incident[chosen]
        parts = []
        for h, e in outcomes:
            new_posterior, p_obs = pomdp.belief_update(posterior[keep], incident, h, e, rule="bayes")
            if belief_rule == "bayes":
                new_av = new_posterior
            else:
                new_av, _ = pomdp.belief_update(belief_av[keep], incident, h, e, rule=belief_rule)
            possible = p_obs > 0
            new_joint = filter_.update(joint[keep][possible], new_posterior[possible], new_av[possible],
                                       chosen[possible], incident[possible], h, e, p_obs[possible])
            parts.append((new_route_ids[possible], chosen[possible], new_av[possible],
                          new_posterior[possible], new_joint,
                          probability[keep][possible] * p_obs[possible]))
        route_id, road, belief_av, posterior, joint, probability = (
            np.concatenate([part[j] for part in parts]) for j in range(6))
        if merge:
            # Histories at the same (road, J, posterior, AV belief) whose routes the policy reads
            # alike (route_memory) are driven alike from here on: one node, their masses summed.
            unique_routes, route_inverse = np.unique(route_id, return_inverse=True)
            memory_id = np.array([memory_ids.setdefault(policy.route_memory(routes[r]), len(memory_ids))
                                  for r in unique_routes.tolist()], dtype=float)[route_inverse]
            first, inverse = distinct_nodes(road, joint, posterior,
                                            np.concatenate([belief_av, memory_id[:, None]], axis=1))
            probability = np.bincount(inverse, weights=probability)
            route_id, road, belief_av, posterior, joint = (
                a[first] for a in (route_id, road, belief_av, posterior, joint))
        if probability.size > max_nodes:
            # Least live mass first: the width pruning adds is the live mass it drops.
            order = np.argsort(probability * filter_.masses(joint)[2], kind="stable")
            dropped = np.zeros(probability.size, dtype=bool)
            dropped[order[: probability.size - max_nodes]] = True
            end(dropped, "pruned", level + 1, "beyond_budget")
            kept = ~dropped
            route_id, road, belief_av, posterior, joint, probability = (
                a[kept] for a in (route_id, road, belief_av, posterior, joint, probability))
        nodes += probability.size
        max_frontier = max(max_frontier, probability.size)

    if batched is not None:
        batched.forget_prefetched()
    pruned = mass["pruned"]
    lower, upper = accepted_bounds(mass["accepted"], pruned)
    return Evaluation(
        policy=policy.name,
        lower=lower,
        upper=upper,
        expected_final_trust=trust_sum / ended_mass if ended_mass > 0 else float("nan"),
        final_trust_lower=trust_sum + (1.0 - ended_mass) * float(levels.min()),
        final_trust_upper=trust_sum + (1.0 - ended_mass) * float(levels.max()),
        expected_junctions=junction_sum / ended_mass if ended_mass > 0 else float("nan"),
        fallback_probability=fallback_mass,
        end_mass=mass,
        nodes=nodes,
        max_frontier=max_frontier,
        seconds=time.perf_counter() - started,
        belief_rule=belief_rule,
        fallback_after=fallback_level,
        max_junctions=max_junctions,
        pruning={"prune_below": prune_below, "max_nodes": max_nodes, "time_limit": time_limit,
                 "pruned_mass": cut, "pruned_nodes": cut_nodes, "first_pruned_level": first_cut_level},
    )


TABLE_CHUNK = 5_000     # nodes moved per batch in evaluate_joint_table (the deadline is checked between)


def evaluate_joint_table(pomdp: TrustPOMDP, spec: Spec, policy, max_junctions: int,
                         belief_rule: BeliefRule = "bayes",
                         max_nodes: int = DEFAULT_MAX_NODES,
                         deadline: float | None = None) -> tuple[float, float]:
    """Certified [lower, upper] of P(accepted within `max_junctions`) for a policy whose decision
    at a node is a function of (junctions driven, road, joint belief, AV belief) alone, asked in
    batches: `policy.action_slots(t, x, joint, beliefs)` (routing.trust_state_table.JointTablePolicy),
    without the fallback. Histories that reach bit-identical (road, J, posterior, AV belief) at the
    same level are merged (their decisions and futures are the same), so this is the unfolding of
    `evaluate_joint` on far fewer nodes; beyond `max_nodes` per level the least likely nodes are
    dropped, their live mass unknown; by `deadline` (time.perf_counter()) the unfolding stops (a
    batch of TABLE_CHUNK nodes or a level's merge is not begun when, at the last one's pace, it
    would end past it) and the live mass of every open node is unknown."""
    town, driver = pomdp.town, pomdp.driver
    compiled = compile_spec(spec, town)
    filter_ = joint_filter(pomdp, compiled.dfa, compiled.labeller)
    outcomes = [(h, e) for h in (0, 1) for e in ((0, 1) if driver.depends_on_performance else (0,))]
    start = town.state_index(spec.start)
    b0 = np.asarray(pomdp.initial_belief, dtype=float)[None, :]
    x, joint, posterior, belief, mass = (np.array([start]), filter_.initial(start, b0[0]), b0.copy(),
                                         b0.copy(), np.ones(1))
    accepted_total, unknown = 0.0, 0.0
    batch_seconds = merge_rate = 0.0       # the last batch's duration, the last merge's per row
    for level in range(max_junctions + 1):
        accepted, _, live = filter_.masses(joint)
        out_of_time = deadline is not None and level > 0 and time.perf_counter() > deadline
        if out_of_time:
            accepted_total += float(mass @ accepted)
            unknown += float(mass @ live)
            break
        ending = (live <= 0) | (level == max_junctions)
        accepted_total += float(mass[ending] @ accepted[ending])
        go = ~ending
        if go.sum() > max_nodes:
            order = np.argsort(-np.where(go, mass, -np.inf), kind="stable")
            dropped = np.zeros(mass.size, dtype=bool)
            dropped[order[max_nodes:]] = True
            dropped &= go
            accepted_total += float(mass[dropped] @ accepted[dropped])
            unknown += float(mass[dropped] @ live[dropped])
            go &= ~dropped
        if not go.any():
            break
        x, joint, posterior, belief, mass = (a[go] for a in (x, joint, posterior, belief, mass))
        parts = []
        late = False
        for begin in range(0, x.size, TABLE_CHUNK):
            # A batch is not begun when the last one's duration would take it past the deadline.
            began = time.perf_counter()
            late = deadline is not None and began + batch_seconds > deadline
            if late:
                # Out of time within the level: the nodes not moved yet keep their accepted
                # mass; their live mass is unknown.
                rest_accepted, _, rest_live = filter_.masses(joint[begin:])
                accepted_total += float(mass[begin:] @ rest_accepted)
                unknown += float(mass[begin:] @ rest_live)
                break
            part = slice(begin, begin + TABLE_CHUNK)
            slots = policy.action_slots(level, x[part], joint[part], belief[part])
            x2 = pomdp.successor_table[x[part], slots]
            incident = pomdp.road_incident[x2]
            for h, e in outcomes:
                new_posterior, p_obs = pomdp.belief_update(posterior[part], incident, h, e)
                new_belief = new_posterior if belief_rule == "bayes" else pomdp.belief_update(
                    belief[part], incident, h, e, rule=belief_rule)[0]
                ok = p_obs > 0
                new_joint = filter_.update(joint[part][ok], new_posterior[ok], new_belief[ok], x2[ok],
                                           incident[ok], h, e, p_obs[ok])
                parts.append((x2[ok], new_joint, new_posterior[ok], new_belief[ok],
                              mass[part][ok] * p_obs[ok]))
            batch_seconds = time.perf_counter() - began
        if not parts:
            break
        x, joint, posterior, belief, mass = (np.concatenate([p[j] for p in parts]) for j in range(5))
        # Nor is the merge, when it would at the last merge's seconds per row.
        if late or (deadline is not None and time.perf_counter() + merge_rate * x.size > deadline):
            # The children of the nodes moved: their accepted mass counts, their live mass is unknown.
            accepted, _, live = filter_.masses(joint)
            accepted_total += float(mass @ accepted)
            unknown += float(mass @ live)
            break
        began = time.perf_counter()
        first, inverse = distinct_nodes(x, joint, posterior, belief)
        mass = np.bincount(inverse, weights=mass)
        x, joint, posterior, belief = x[first], joint[first], posterior[first], belief[first]
        merge_rate = (time.perf_counter() - began) / inverse.size
    return accepted_bounds(accepted_total, unknown)
