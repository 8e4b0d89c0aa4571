"""An exact-rational brute force for specs that test the hidden trust (docs/trust_states.md).

The joint law J(i, q) of the hidden index i (trust, or (type, trust) of a population's lifted
model) and the DFA state q given the observations, in integers: the exact process of
threshold_cases.py (the model's numbers as the decimals they print as, `_ExactFilter`'s integer
matrices) carried over (i, q). After driving x' and seeing o,

    J'(i', q') = Σ_{i, q} J(i, q) ℓ_o(i) T_o(i, i') [q' = δ(q, L(x', θ(i'), b'))]

with b' the AV's exact Bayes belief (belief atoms, decided in integers) and θ(i') the trust level
a trust-state atom reads (`base_trust_index`). P(o) = Σ J ℓ_o / Σ J exactly; the value of a history
is its accepted share of J once no live mass is left or at the horizon.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from tests.policies.synthesis.threshold_cases import ExactLabelling, _ExactFilter, _outcomes
from trustroute.policies.belief.driver_types import base_trust_index, n_types_of
from trustroute.policies.belief.trust_state_filter import joint_filter
from trustroute.policies.evaluation.node_state import HiddenState, hidden_root
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import TrustPOMDP
from trustroute.policies.routing.trust_state_table import JointTablePolicy


class _Joint:
    """The exact joint filter of one spec on one model (module docstring)."""

    def __init__(self, pomdp: TrustPOMDP, spec: Spec) -> None:
        self.compiled = compile_spec(spec, pomdp.town)
        self.dfa = self.compiled.dfa
        self.av = _ExactFilter.of(pomdp, "bayes")
        self.labels = ExactLabelling(self.compiled.labeller, pomdp.n_trust)
        self.trust = base_trust_index(pomdp.driver)
        self.n, self.n_q = pomdp.n_trust, int(self.dfa.n_states)
        self.types = n_types_of(pomdp.driver)
        self.accepting = np.asarray(self.dfa.accepting, dtype=bool)
        self.live = ~(self.accepting | np.asarray(self.dfa.rejecting, dtype=bool))

    def successors(self, x: int, belief: tuple[int, ...]) -> np.ndarray:
        """int [n_q, n]: δ(q, L(x, θ(i), belief)) for every q and hidden index i."""
        valuation = self.labels.valuations(x, belief, self.trust)
        return np.stack([self.dfa.step_many(np.full(self.n, q), valuation) for q in range(self.n_q)])

    def initial(self, x: int, block: int | None) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """(J, b) at the start: i ~ the prior (restricted to type `block`'s hidden indices when
        given, the AV's belief the whole prior), q0 read at the start road."""
        prior = self.av.prior
        keep = [block is None or i // (self.n // self.types) == block for i in range(self.n)]
        to = self.successors(x, prior)[self.dfa.initial]
        joint = [0] * (self.n * self.n_q)
        for i, p in enumerate(prior):
            if keep[i]:
                joint[i * self.n_q + int(to[i])] += p
        return tuple(joint), prior

    def step(self, joint: tuple[int, ...], x: int, belief: tuple[int, ...], symbol
             ) -> tuple[Fraction, tuple[int, ...], tuple[int, ...]]:
        """(P(symbol), J', b') after driving x and seeing `symbol`."""
        like, scale = self.av.likelihood[symbol]
        weight = sum(joint[i * self.n_q + q] * like[i] for i in range(self.n) for q in range(self.n_q))
        if weight == 0:
            return Fraction(0), joint, belief
        posterior = self.av.update_belief(belief, symbol)
        to = self.successors(x, posterior)
        matrix = self.av.update[symbol]
        image = [0] * (self.n * self.n_q)
        for i in range(self.n):
            for q in range(self.n_q):
                mass = joint[i * self.n_q + q]
                if mass:
                    for j, m in enumerate(matrix[i]):
                        if m:
                            image[j * self.n_q + int(to[q, j])] += mass * m
        return Fraction(weight, sum(joint) * scale), tuple(image), posterior

    def share(self, joint: tuple[int, ...], states: np.ndarray) -> Fraction:
        return Fraction(sum(joint[i * self.n_q + q] for i in range(self.n) for q in np.flatnonzero(states)),
                        sum(joint))


def exact_joint_value(pomdp: TrustPOMDP, spec: Spec, horizon: int, policy: JointTablePolicy | None = None,
                      block: int | None = None) -> Fraction:
    """max over policies (or the value of `policy`, acting on the vehicle's float joint filter:
    policies/evaluation/node_state.py's HiddenState, one history) of P(spec accepted within
    `horizon` junctions), exactly; with `block` the true driver is that type of the population
    (the AV filtering on the lifted model `pomdp`). A policy's slot -1 ends the episode there (the
    accepted share of the joint law counts, as at the horizon)."""
    town = pomdp.town
    model = _Joint(pomdp, spec)
    outcomes = _outcomes(pomdp.driver)
    successors = [[town.state_index(s) for s in town.successors(road)] for road in town.states]
    memo: dict = {}

    def moves(t: int, x: int, vehicle: HiddenState | None) -> list[int]:
        if policy is None or vehicle is None:
            return successors[x]
        slot = int(policy.action_slots(t, np.array([x]), vehicle.joint, vehicle.belief)[0])
        return [] if slot < 0 else [successors[x][slot]]

    def value(t: int, x: int, joint: tuple[int, ...], belief: tuple[int, ...],
              vehicle: HiddenState | None) -> Fraction:
        if t == horizon or model.share(joint, model.live) == 0:
            return model.share(joint, model.accepting)
        key = (t, x, joint, belief, None if vehicle is None else (vehicle.joint.tobytes(),
                                                                  vehicle.belief.tobytes()))
        if key not in memo:
            ahead = moves(t, x, vehicle)
            best = Fraction(0) if ahead else model.share(joint, model.accepting)
            for x2 in ahead:
                total = Fraction(0)
                for h, e in outcomes:
                    i = int(pomdp.road_incident[x2])
                    probability, joint2, belief2 = model.step(joint, x2, belief, (i, h, e))
                    if probability == 0:
                        continue
                    road = np.array([x2])
                    follow = None if vehicle is None else vehicle.children(
                        road, h, e, vehicle.observation_probability(road, h, e))
                    total += probability * value(t + 1, x2, joint2, belief2, follow)
                best = max(best, total)
            memo[key] = best
        return memo[key]

    start = town.state_index(spec.start)
    joint, belief = model.initial(start, block)
    vehicle = None if policy is None else hidden_root(
        joint_filter(pomdp, model.dfa, model.compiled.labeller), start, "bayes")
    return value(0, start, joint, belief, vehicle)
