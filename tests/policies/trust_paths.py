"""Brute force over trust paths: the reference for specs that test the hidden trust.

Every history of observations is enumerated depth first, and at every history every trust path
θ0, θ1, ... separately (no merging of paths: that merging is what the joint filter does), each
with its probability P(θ path, observations) and its own DFA run on its own labels. The AV's
belief is the normalised sum of path probabilities by current trust (the definition of the
posterior), the DFA state a policy is told the likeliest one over paths, and the joint belief
J(θ, q) the normalised path probabilities. Labels are computed
here from the spec's definitions, not by policies/logic/labelling.py. Exponential: small towns,
a few junctions.
"""

from __future__ import annotations

import numpy as np

from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.routing.protocol import DecisionContext


class _Paths:
    def __init__(self, pomdp, spec):
        self.pomdp, self.spec, self.town, self.driver = pomdp, spec, pomdp.town, pomdp.driver
        self.dfa = build_dfa(spec)
        self.n_t = self.driver.n_trust
        self.outcomes = [(h, e) for h in (0, 1)
                         for e in ((0, 1) if self.driver.depends_on_performance else (0,))]

    def valuations(self, road: str, belief: np.ndarray, theta: np.ndarray) -> np.ndarray:
        out = np.zeros((theta.size, len(self.dfa.atoms)), dtype=bool)
        for j, atom in enumerate(self.dfa.atoms):
            if atom in self.spec.state_atoms:
                out[:, j] = road in self.spec.state_atoms[atom]
            elif atom in self.spec.belief_atoms:
                definition = self.spec.belief_atoms[atom]
                out[:, j] = definition.offset - float(np.dot(definition.coeffs, belief)) < 0
            else:
                definition = self.spec.trust_atoms[atom]
                on_road = definition.roads is None or road in definition.roads
                levels = np.asarray(self.driver.trust_levels)[theta]
                out[:, j] = on_road & np.isin(levels, sorted(definition.trust))
        return out

    def belief(self, theta: np.ndarray, weight: np.ndarray) -> np.ndarray:
        b = np.bincount(theta, weights=weight, minlength=self.n_t)
        return b / b.sum()

    def start(self):
        b0 = np.asarray(self.driver.initial_belief, dtype=float)
        theta = np.flatnonzero(b0 > 0)
        weight = b0[theta]
        q = self.dfa.step_many(np.full(theta.size, self.dfa.initial),
                               self.valuations(self.spec.start, b0, theta))
        return theta, weight, np.asarray(q), b0

    def step(self, theta, weight, q, road: str, h: int, e: int):
        """Paths extended by driving `road` and seeing (h, e); None when impossible."""
        inc = self.driver.incident_index(self.town.incident(road))
        p_obs = (self.driver.takeover_probability[inc, theta] if h else
                 1 - self.driver.takeover_probability[inc, theta])
        p_obs = p_obs * (self.driver.failure_probability[inc, theta] if e else
                         1 - self.driver.failure_probability[inc, theta])
        moved = (weight * p_obs)[:, None] * self.driver.trust_transition[inc, h, e, theta]   # [P, θ']
        path, theta2 = np.nonzero(moved > 0)
        if path.size == 0:
            return None
        weight2 = moved[path, theta2]
        belief = self.belief(theta2, weight2)
        # A path's labels depend on its own trust only (the road and belief are the history's), so
        # each path's DFA step is read from the steps of every (q, θ') pair: the same successors,
        # without stepping and labelling every path one by one.
        n_q = self.dfa.n_states
        levels = np.arange(self.n_t)
        pairs = self.dfa.step_many(np.repeat(np.arange(n_q), self.n_t),
                                   np.tile(self.valuations(road, belief, levels), (n_q, 1)))
        q2 = np.asarray(pairs).reshape(n_q, self.n_t)[q[path], theta2]
        return theta2, weight2, q2, belief

    def accepted(self, weight, q) -> float:
        return float(weight[self.dfa.accepting[q]].sum())

    def settled(self, q) -> bool:
        return bool((self.dfa.accepting[q] | self.dfa.rejecting[q]).all())

    def told_q(self, weight, q) -> int:
        return int(np.argmax(np.bincount(q, weights=weight, minlength=self.dfa.n_states)))

    def joint(self, theta, weight, q) -> np.ndarray:
        """J(θ, q): the normalised path probabilities by (current trust, DFA state)."""
        n_q = self.dfa.n_states
        table = np.bincount(theta * n_q + q, weights=weight, minlength=self.n_t * n_q)
        return (table / table.sum()).reshape(self.n_t, n_q)


def policy_value(pomdp, spec, policy, max_junctions: int) -> float:
    """P(spec satisfied) of `policy` (no fallback wrapper is added), episodes ending where the
    policy finishes or at `max_junctions`."""
    paths = _Paths(pomdp, spec)
    return _policy_mass(paths, spec, policy, max_junctions,
                        lambda theta, weight, q: paths.accepted(weight, q))


def policy_value_by_type(pomdp, spec, policy, max_junctions: int, n_types: int) -> np.ndarray:
    """P(spec satisfied, type k) [n_types] of `policy` for a type-aware model whose hidden index is
    k·n + θ (policies/belief/driver_types.py), as `policy_value` (the AV's belief, told state and
    joint belief over every path of every type; the accepted path mass split by its type)."""
    paths = _Paths(pomdp, spec)
    n = paths.n_t // n_types

    def accepted(theta, weight, q) -> np.ndarray:
        done = paths.dfa.accepting[q]
        return np.bincount(theta[done] // n, weights=weight[done], minlength=n_types)

    return _policy_mass(paths, spec, policy, max_junctions, accepted)


def _policy_mass(paths: _Paths, spec, policy, max_junctions: int, accepted):
    def visit(route, theta, weight, q, belief):
        if paths.settled(q):
            return accepted(theta, weight, q)
        context = DecisionContext(route=tuple(route), dfa_state=paths.told_q(weight, q), belief=belief,
                                  joint=paths.joint(theta, weight, q))
        if policy.finished(context) or len(route) - 1 == max_junctions:
            return accepted(theta, weight, q)
        road = paths.town.successor(route[-1], policy.next_junction(context))
        total = 0.0
        for h, e in paths.outcomes:
            nxt = paths.step(theta, weight, q, road, h, e)
            if nxt is not None:
                total = total + visit(route + [road], *nxt)
        return total

    return visit([spec.start], *paths.start())


def optimum(pomdp, spec, horizon: int) -> float:
    """max over policies of P(spec accepted within `horizon` junctions), over every action."""
    paths = _Paths(pomdp, spec)

    def visit(route, theta, weight, q, belief) -> float:
        if paths.settled(q) or len(route) - 1 == horizon:
            return paths.accepted(weight, q)
        best = 0.0
        for junction in paths.town.actions(route[-1]):
            road = paths.town.successor(route[-1], junction)
            total = 0.0
            for h, e in paths.outcomes:
                nxt = paths.step(theta, weight, q, road, h, e)
                if nxt is not None:
                    total += visit(route + [road], *nxt)
            best = max(best, total)
        return best

    return visit([spec.start], *paths.start())


def robust_optimum(pomdp, spec, horizon: int, weights: np.ndarray) -> float:
    """max over deterministic history-dependent policies of min_k P(spec accepted within `horizon`
    junctions | type k), for a type-aware model whose hidden index is k·n + θ with type prior
    `weights`: at every history the set of per-type accepted-mass vectors the policies below it
    reach (its Pareto front), a choice of one action per history combining its observations' sets."""
    paths = _Paths(pomdp, spec)
    n_types = len(weights)
    n = paths.n_t // n_types

    def front(vectors: np.ndarray) -> np.ndarray:
        vectors = np.unique(np.round(vectors, 14), axis=0)
        keep = [i for i, v in enumerate(vectors)
                if not any((w >= v).all() and (w > v).any() for w in vectors)]
        return vectors[keep]

    def visit(route, theta, weight, q, belief) -> np.ndarray:
        if paths.settled(q) or len(route) - 1 == horizon:
            done = paths.dfa.accepting[q]
            return np.bincount(theta[done] // n, weights=weight[done], minlength=n_types)[None, :]
        reached = []
        for junction in paths.town.actions(route[-1]):
            road = paths.town.successor(route[-1], junction)
            total = np.zeros((1, n_types))
            for h, e in paths.outcomes:
                nxt = paths.step(theta, weight, q, road, h, e)
                if nxt is not None:
                    child = visit(route + [road], *nxt)
                    total = front((total[:, None, :] + child[None, :, :]).reshape(-1, n_types))
            reached.append(total)
        return front(np.concatenate(reached))

    masses = visit([spec.start], *paths.start())
    return float((masses / np.asarray(weights, dtype=float)).min(axis=1).max())
