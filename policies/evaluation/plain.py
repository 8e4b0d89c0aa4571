"""Exact evaluation of any routing policy in the trust POMDP: P(spec satisfied), final trust.

Unfolds the policy's tree of episodes level by level (one level per junction), in numpy.
A node is one history of observations: its route, the spec's DFA state q_t, the AV's belief
b_t (which drives decisions and belief labels) and the true posterior over trust given the
observations (Bayes; equal to the AV's belief under the default rule). Because trust is hidden
and the posterior is the exact conditional law of θ given the history, the probability of each
observation at a node is Σθ posterior(θ) P(h, e | θ, inc) and the expected final trust is
Σ P(node) posterior_node · levels over the nodes where episodes end — no sampling anywhere.

A branch ends by the episode rules (policies/routing/episode_rules.py): when the DFA accepts
(satisfied), when it can no longer accept (rejected), when the policy declares it finished
(destination reached: the trust-free route or the fallback completion is done), or at the
episode's junction cap. Branches with tiny probability are
pruned and their mass reported, so the result is a certified interval [lower, upper]
(lower = mass proven satisfied, upper = lower + pruned mass).

Policies are asked once per distinct (route, DFA state, AV belief). A policy may also offer
`route_determined(context) -> bool` (True: its decision and `finished` here are the same for
every belief and non-accepting DFA state on this route, as for the trust-free policy and the
fallback phase); it is then asked once per route, which keeps deep trees fast.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from trustroute.networks.town import Town
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.routing.episode_rules import (
    ACCEPTED,
    DEFAULT_JUNCTION_CAP,
    REJECTED,
    decide,
    dfa_verdicts,
    episode_policy,
)
from trustroute.policies.routing.fallback import DEFAULT_FALLBACK_AFTER, FallbackPolicy
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

DEFAULT_PRUNE_BELOW = 1e-12
DEFAULT_MAX_NODES = 2_000_000


@dataclass(frozen=True)
class Evaluation:
    """Certified value of a policy: lower <= P(satisfied) <= upper, and trust at episode end.

    end_mass: probability of each way an episode ends ("accepted", "rejected", "destination",
    "cap") plus "pruned" (branches not followed to the end; the width of the interval).
    """

    policy: str
    lower: float
    upper: float
    expected_final_trust: float
    final_trust_lower: float
    final_trust_upper: float
    expected_junctions: float
    fallback_probability: float
    end_mass: dict[str, float]
    nodes: int
    max_frontier: int
    seconds: float
    belief_rule: str
    fallback_after: int | None
    max_junctions: int
    reference_accepted: float | None = None   # mass the reference reading accepts (`reference`)
    pruning: dict | None = None   # the joint unfolding's limits and what each cut (evaluate_joint)

    @property
    def gap(self) -> float:
        return self.upper - self.lower

    @property
    def satisfaction_probability(self) -> float:
        """Midpoint of the certified interval (equal to both ends when nothing was pruned)."""
        return 0.5 * (self.lower + self.upper)

    def to_dict(self) -> dict:
        out = asdict(self)
        for optional in ("reference_accepted", "pruning"):
            if out[optional] is None:
                del out[optional]
        out["gap"] = self.gap
        out["satisfaction_probability"] = self.satisfaction_probability
        return out



def extend_routes(routes: list[tuple[str, ...]], route_id: np.ndarray, chosen: np.ndarray,
                  states: tuple[str, ...] | list[str]) -> np.ndarray:
    """Append one route per distinct (old route, next road) to `routes`; the new ids, per node."""
    n_states = len(states)
    pair = route_id * n_states + chosen
    unique_pairs, pair_inverse = np.unique(pair, return_inverse=True)
    pair_ids = np.arange(len(routes), len(routes) + unique_pairs.size)
    for rid, x2 in zip((unique_pairs // n_states).tolist(), (unique_pairs % n_states).tolist(),
                       strict=True):
        routes.append(routes[rid] + (states[x2],))
    return pair_ids[pair_inverse]


def accepted_bounds(accepted: float, pruned: float) -> tuple[float, float]:
    """[lower, upper] of P(accepted) from the accepted and pruned masses.

    Summed path masses can round past 1; a probability cannot, and upper >= lower must hold.
    """
    lower = min(accepted, 1.0)
    return lower, min(1.0, lower + pruned)

def decide_node(policy: RoutingPolicy, context: DecisionContext, town: Town, road: int, level: int,
                max_junctions: int, fallback_level: int | None,
                successor_index: dict) -> tuple[bool, bool, int]:
    """(finished here, the fallback first drives here, next road index or -1) for one tree node, by
    the episode rules; road is the index of context.road."""
    decision = decide(policy, context, town, max_junctions)
    if decision.end is not None:
        return decision.end == "destination", False, -1
    return (False, fallback_level == level and decision.fallback, successor_index[(road, decision.junction)])


def evaluate(pomdp: TrustPOMDP, spec: Spec, policy: RoutingPolicy,
             fallback_after: int | None = DEFAULT_FALLBACK_AFTER, max_junctions: int = DEFAULT_JUNCTION_CAP,
             belief_rule: BeliefRule = "bayes", prune_below: float = DEFAULT_PRUNE_BELOW,
             max_nodes: int = DEFAULT_MAX_NODES, truth: TrustPOMDP | None = None,
             reference: tuple[TrustPOMDP, Spec] | None = None) -> Evaluation:
    """Exact (or tightly certified) satisfaction probability of `policy` for `spec`.

    fallback_after: wrap the policy with the study's rule after that many junctions
    (None: evaluate the policy as given; a policy already wrapped is not wrapped again).
    max_junctions: the episode's hard cap; an episode still running there is unsatisfied.
    belief_rule: the AV's filter ("bayes", or the authors' "paper" update); observation
    probabilities and the final trust always use the true (Bayes) posterior.
    prune_below / max_nodes: branches below this probability, or beyond this frontier size
    (smallest first), are not followed; their mass widens [lower, upper].
    truth: the driver the episodes are driven with, when it is not the AV's model (a driver type,
    another population, docs/driver_types.md "Exact values per type"): observations are drawn
    from its exact posterior (starting from its initial belief) while the AV's belief, which drives
    decisions and labels, runs `pomdp`'s filter; an observation the AV deems impossible leaves the
    AV's belief unchanged, as in the episode tracker. The final trust is the truth's.
    reference (pomdp_ref, spec_ref): also read the spec with another belief, the Bayes filter of
    pomdp_ref on the same observations (e.g. the posterior under the true population), without
    changing what the vehicle does: `reference_accepted` is the mass of episodes that this
    reading accepts by the time the vehicle's episode ends (docs/driver_types.md, "Limits").
    """
    started = time.perf_counter()
    town, driver = pomdp.town, pomdp.driver
    policy = episode_policy(policy, town, spec, fallback_after)
    fallback_level = policy.after if isinstance(policy, FallbackPolicy) else None
    compiled = compile_spec(spec, town)
    truth_pomdp = pomdp if truth is None else truth
    levels = np.asarray(truth_pomdp.driver.trust_levels, dtype=float)
    performance = driver.depends_on_performance or truth_pomdp.driver.depends_on_performance
    outcomes = [(h, e) for h in (0, 1) for e in ((0, 1) if performance else (0,))]
    successor_index = {(x, j): town.state_index(town.successor(road, j))
                       for x, road in enumerate(town.states) for j in town.actions(road)}

    start = town.state_index(spec.start)
    routes: list[tuple[str, ...]] = [(spec.start,)]
    route_id = np.zeros(1, dtype=np.int64)
    road = np.array([start], dtype=np.int64)
    belief_av = np.asarray(pomdp.initial_belief, dtype=float)[None, :].copy()
    posterior = (belief_av.copy() if truth is None
                 else np.asarray(truth.initial_belief, dtype=float)[None, :].copy())
    probability = np.ones(1)
    q = compiled.initial_states(belief_av)
    if reference is not None:
        ref_pomdp, ref_compiled = reference[0], compile_spec(reference[1], town)
        ref_belief = np.asarray(ref_pomdp.initial_belief, dtype=float)[None, :].copy()
        q_ref = ref_compiled.initial_states(ref_belief)
    else:
        ref_belief, q_ref = np.zeros((1, 0)), np.zeros(1, dtype=np.int64)
    ref_mass = 0.0

    mass = {"accepted": 0.0, "rejected": 0.0, "destination": 0.0, "cap": 0.0, "pruned": 0.0}
    trust_sum = 0.0          # Σ P(end node) E[θ | node] over ended (non-pruned) nodes
    junction_sum = 0.0
    fallback_mass = 0.0
    nodes = 1
    max_frontier = 1

    def end(mask: np.ndarray, reason: str, level: int) -> None:
        nonlocal trust_sum, junction_sum, ref_mass
        p = probability[mask]
        if reference is not None:
            ref_mass += float(p[ref_compiled.accepting[q_ref[mask]]].sum())
        mass[reason] += float(p.sum())
        trust_sum += float(p @ (posterior[mask] @ levels))
        junction_sum += float(p.sum()) * level

    for level in range(max_junctions + 1):
        verdict = dfa_verdicts(compiled, q)
        accepted, rejected = verdict == ACCEPTED, verdict == REJECTED
        end(accepted, "accepted", level)
        end(rejected, "rejected", level)
        alive = ~(accepted | rejected)
        tiny = alive & (probability < prune_below)
        mass["pruned"] += float(probability[tiny].sum())
        alive &= ~tiny
        if not alive.any():
            break
        keep = np.flatnonzero(alive)

        # One decision per distinct (route, DFA state, AV belief), or per route when the policy
        # says its decision there depends on the route only (trust-free route, fallback phase).
        finished = np.zeros(keep.size, dtype=bool)
        fired = np.zeros(keep.size, dtype=bool)
        chosen = np.full(keep.size, -1, dtype=np.int64)
        unique_routes, first, inverse = np.unique(route_id[keep], return_index=True, return_inverse=True)
        order = np.argsort(inverse, kind="stable")
        bounds = np.searchsorted(inverse[order], np.arange(unique_routes.size + 1))
        for r, rid in enumerate(unique_routes.tolist()):
            members = order[bounds[r]:bounds[r + 1]]
            i0 = keep[first[r]]
            context = DecisionContext(route=routes[rid], dfa_state=int(q[i0]), belief=belief_av[i0])
            if policy.route_determined(context):
                finished[members], fired[members], chosen[members] = decide_node(
                    policy, context, town, int(road[i0]), level, max_junctions, fallback_level,
                    successor_index)
                continue
            decisions: dict[tuple[int, bytes], tuple[bool, bool, int]] = {}
            for k in members.tolist():
                i = keep[k]
                key = (int(q[i]), belief_av[i].tobytes())
                decision = decisions.get(key)
                if decision is None:
                    context = DecisionContext(route=routes[rid], dfa_state=key[0], belief=belief_av[i])
                    decision = decide_node(policy, context, town, int(road[i]), level, max_junctions,
                                       fallback_level, successor_index)
                    decisions[key] = decision
                finished[k], fired[k], chosen[k] = decision
        end(keep[finished], "destination", level)
        if level == max_junctions:
            end(keep[~finished], "cap", level)
            break
        fallback_mass += float(probability[keep[fired]].sum())
        keep, chosen = keep[~finished], chosen[~finished]
        if keep.size == 0:
            break

        new_route_ids = extend_routes(routes, route_id[keep], chosen, town.states)

        # Branch on the observation (h, e) at the new road.
        incident = pomdp.road_incident[chosen]
        true_incident = truth_pomdp.road_incident[chosen]
        parts = []
        for h, e in outcomes:
            new_posterior, p_obs = truth_pomdp.belief_update(posterior[keep], true_incident, h, e,
                                                             rule="bayes")
            if belief_rule == "bayes" and truth is None:
                new_av = new_posterior
            else:
                new_av, _ = pomdp.belief_update(belief_av[keep], incident, h, e, rule=belief_rule)
                if truth is not None:
                    impossible = ~(new_av.sum(axis=1) > 0)
                    new_av[impossible] = belief_av[keep][impossible]
            possible = p_obs > 0
            new_ref = ref_belief[keep]
            if reference is not None:
                new_ref, _ = ref_pomdp.belief_update(new_ref, ref_pomdp.road_incident[chosen], h, e)
                stuck = ~(new_ref.sum(axis=1) > 0)
                new_ref[stuck] = ref_belief[keep][stuck]
            parts.append((new_route_ids[possible], chosen[possible], q[keep][possible],
                          new_av[possible], new_posterior[possible],
                          probability[keep][possible] * p_obs[possible], q_ref[keep][possible],
                          new_ref[possible]))
        route_id, road, q_before, belief_av, posterior, probability, q_ref, ref_belief = (
            np.concatenate([part[j] for part in parts]) for j in range(8))
        q = compiled.step(q_before, road, belief_av)
        if reference is not None:
            q_ref = ref_compiled.step(q_ref, road, ref_belief)
        if probability.size > max_nodes:
            order = np.argsort(probability)
            dropped = order[: probability.size - max_nodes]
            mass["pruned"] += float(probability[dropped].sum())
            kept = np.sort(order[probability.size - max_nodes:])
            route_id, road, q, belief_av, posterior, probability, q_ref, ref_belief = (
                a[kept] for a in (route_id, road, q, belief_av, posterior, probability, q_ref, ref_belief))
        nodes += probability.size
        max_frontier = max(max_frontier, probability.size)

    ended = 1.0 - mass["pruned"]
    pruned = mass["pruned"]
    trust_point = trust_sum / ended if ended > 0 else float("nan")
    lower, upper = accepted_bounds(mass["accepted"], pruned)
    return Evaluation(
        policy=policy.name,
        lower=lower,
        upper=upper,
        expected_final_trust=trust_point,
        final_trust_lower=trust_sum + pruned * float(levels.min()),
        final_trust_upper=trust_sum + pruned * float(levels.max()),
        expected_junctions=junction_sum / ended if ended > 0 else float("nan"),
        fallback_probability=fallback_mass,
        end_mass=mass,
        nodes=nodes,
        max_frontier=max_frontier,
        seconds=time.perf_counter() - started,
        belief_rule=belief_rule,
        fallback_after=fallback_level,
        max_junctions=max_junctions,
        reference_accepted=None if reference is None else min(ref_mass, 1.0),
    )
