"""Exact optimum for small horizons by depth-first search over the action/observation tree.

V_t(x, q, b) = 1 if q accepts; 0 if q rejects or t = H; else
max over next junctions of Σ_o P(o | b) V_{t+1}(x', δ(q, L(x', f_o(b))), f_o(b)),
memoised on (t, x, q, belief bytes, word). Belief labels are those of the exact filter (decided in
floats where they can be, exactly on the history's word elsewhere: policies/belief/exact_labels.py).
No abstraction, no pruning: the reference the scalable solver (policies/synthesis/belief_synthesis.py)
is tested against. Exponential in H; meant for H <= 12. It shares only the model arrays
(TrustPOMDP), the labeller and its exact decisions with the solver.
"""

from __future__ import annotations

import numpy as np

from trustroute.policies.belief.exact_labels import exact_labels, symbol_code
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP

MAX_EXACT_HORIZON = 12


def exact_optimum(pomdp: TrustPOMDP, spec: Spec, horizon: int, belief_rule: BeliefRule = "bayes") -> float:
    """max over policies of P(spec accepted within `horizon` junctions), exactly (float arithmetic)."""
    if not 0 <= horizon <= MAX_EXACT_HORIZON:
        raise ValueError(f"exact search is for horizons 0..{MAX_EXACT_HORIZON}, got {horizon}")
    town, driver = pomdp.town, pomdp.driver
    compiled = compile_spec(spec, town)
    accepting, rejecting = compiled.accepting, compiled.rejecting
    outcomes = [(h, e) for h in (0, 1) for e in ((0, 1) if driver.depends_on_performance else (0,))]
    successors = [[town.state_index(s) for s in town.successors(road)] for road in town.states]
    labels = exact_labels(pomdp, compiled.labeller, belief_rule)
    memo: dict[tuple[int, int, int, bytes, int], float] = {}

    def observed(belief: np.ndarray, word: int, incident: int) -> list[tuple[float, np.ndarray, np.ndarray]]:
        """(P(o | b), f_o(b), word + o) of every possible outcome o at a road of `incident`, in
        outcome order."""
        found = []
        for h, e in outcomes:
            posterior, probability = pomdp.belief_update(belief, incident, h, e, rule=belief_rule)
            p = float(probability[0])
            if p > 0.0:
                word2 = labels.filter.extend(np.array([word]), symbol_code(incident, h, e))
                found.append((p, posterior[0], word2))
        return found

    def value(t: int, x: int, q: int, belief: np.ndarray, word: int) -> float:
        if accepting[q]:
            return 1.0
        if rejecting[q] or t == horizon:
            return 0.0
        key = (t, x, q, belief.tobytes(), word)
        cached = memo.get(key)
        if cached is not None:
            return cached
        best = 0.0
        # successors with one incident type see the same outcomes: filtered once per incident
        by_incident: dict[int, list[tuple[float, np.ndarray, np.ndarray]]] = {}
        for x2 in successors[x]:
            incident = int(pomdp.road_incident[x2])
            if incident not in by_incident:
                by_incident[incident] = observed(belief, word, incident)
            total = 0.0
            for p, b2, word2 in by_incident[incident]:
                q2 = int(labels.step(np.array([q]), np.array([x2]), b2[None], word2)[0])
                total += p * value(t + 1, x2, q2, b2, int(word2[0]))
            best = max(best, total)
        memo[key] = best
        return best

    start = town.state_index(spec.start)
    b0 = np.asarray(pomdp.initial_belief, dtype=float)
    q0 = int(labels.step(np.array([compiled.dfa.initial]), np.array([start]), b0[None],
                         np.zeros(1, dtype=np.int64))[0])
    return value(0, start, q0, b0, 0)
