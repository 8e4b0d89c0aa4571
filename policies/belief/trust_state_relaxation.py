"""The trust-state relaxation: an upper bound on any policy's value from (road, θ, q).

R(x, θ, q) is the value of a relaxation that observes θ and q and may choose the value of every
belief atom; it bounds the value of any policy from above (docs/trust_states.md). It is computed
by backward induction (bounded) or by value iteration from above (unbounded), each iterate plus
a margin of 1e-12 so that floating-point rounding cannot take it below the true value.
`RelaxedGuide` turns it into action values at a joint belief: the trust-state search expands its
guided nodes with it and the trust-state table acts with it off its stored rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trustroute.policies.belief.driver_types import base_trust_index
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.dfa import DFA
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import TrustPOMDP

RELAXATION_MARGIN = 1e-12
RELAXATION_TOLERANCE = 1e-10
MAX_RELAXATION_ITERATIONS = 100_000



def relaxed_next_q(pomdp: TrustPOMDP, spec: Spec, dfa: DFA, labeller: Labeller) -> np.ndarray:
    """int [n_q, n_x, n_trust, 2**m]: δ(q, L(x', θ', bits)) with the m belief atoms set by bits."""
    n_x, n_t, n_q = pomdp.n_states, pomdp.n_trust, int(dfa.n_states)
    m = int(labeller.belief_columns.size)
    q, x, t, bits = (a.ravel() for a in np.meshgrid(np.arange(n_q), np.arange(n_x), np.arange(n_t),
                                                     np.arange(2 ** m), indexing="ij"))
    valuations = labeller.valuations(x, np.zeros((x.size, n_t)),
                                     base_trust_index(pomdp.driver)[t] if labeller.reads_trust else None)
    for j, column in enumerate(labeller.belief_columns.tolist()):
        valuations[:, column] = (bits >> j) & 1
    return np.asarray(dfa.step_many(q, valuations), dtype=np.int64).reshape(n_q, n_x, n_t, 2 ** m)


def over_bits(values: np.ndarray, next_q: np.ndarray) -> np.ndarray:
    """[q, x, θ]: max over the belief bits of values[x, θ, δ(q, L(x, θ, bits))], for values
    [n_x, n_trust, n_q] and next_q [n_q, n_x, n_trust, bits] (relaxed_next_q)."""
    roads = np.arange(values.shape[0])[None, :, None, None]
    trust = np.arange(values.shape[1])[None, None, :, None]
    return values[roads, trust, next_q].max(axis=3)


def trust_move(pomdp: TrustPOMDP) -> np.ndarray:
    """[incident, θ, θ']: P(θ' | θ, incident), summed over the observations (h, e)."""
    return np.einsum("ihet,ihetu->itu", pomdp.observation_likelihood, pomdp.driver.trust_transition)


def observation_and_trust(pomdp: TrustPOMDP) -> np.ndarray:
    """[incident, h, e, θ, θ']: P(h, e, θ' | θ, incident), the observation and the next trust."""
    return pomdp.observation_likelihood[..., None] * pomdp.driver.trust_transition


def accepted_on_arrival(accepting: np.ndarray, next_q: np.ndarray) -> np.ndarray:
    """[q, x, θ]: 1 where arriving on road x with trust θ from DFA state q accepts for the best
    belief bits, else 0."""
    return np.asarray(accepting, dtype=float)[next_q].max(axis=3)


def relaxed_values(pomdp: TrustPOMDP, spec: Spec, horizon: int | None = None) -> np.ndarray:
    """R [n_x, n_trust, n_q] (unbounded), or [horizon + 1, n_x, n_trust, n_q] with R[k] for k
    junctions left: upper bounds on P(accepted) from (x, θ, q) for any policy."""
    compiled = compile_spec(spec, pomdp.town)
    dfa, labeller = compiled.dfa, compiled.labeller
    next_q = relaxed_next_q(pomdp, spec, dfa, labeller)
    n_x, n_t, n_q = pomdp.n_states, pomdp.n_trust, int(dfa.n_states)
    accepting = np.asarray(dfa.accepting, dtype=bool)
    rejecting = np.asarray(dfa.rejecting, dtype=bool) & ~accepting
    # P(θ' | θ, inc) summed over the observations: the relaxation sees θ, so (h, e) do not matter.
    move = trust_move(pomdp)
    successors = pomdp.successor_table
    valid = successors >= 0
    x2 = np.where(valid, successors, 0)                           # [n_x, slots]
    incident = pomdp.road_incident[x2]

    def backup(values: np.ndarray) -> np.ndarray:
        best = over_bits(values, next_q)                          # [q, x', θ']
        # per (x, slot, θ, q): Σ_θ' move[inc(x2)][θ, θ'] best[q, x2, θ']
        expected = np.einsum("astu,asqu->astq", move[incident], best.transpose(1, 0, 2)[x2])
        expected = np.where(valid[:, :, None, None], expected, -np.inf).max(axis=1)
        out = np.minimum(1.0, expected + RELAXATION_MARGIN)
        out[:, :, accepting] = 1.0
        out[:, :, rejecting] = 0.0
        return out

    if horizon is not None:
        table = np.zeros((horizon + 1, n_x, n_t, n_q))
        table[0, :, :, accepting] = 1.0
        for k in range(1, horizon + 1):
            table[k] = backup(table[k - 1])
        return table
    values = np.ones((n_x, n_t, n_q))
    values[:, :, rejecting] = 0.0
    for _ in range(MAX_RELAXATION_ITERATIONS):
        new = backup(values)
        change = float(np.max(values - new)) if new.size else 0.0
        values = new
        if change <= RELAXATION_TOLERANCE:
            break
    return values



def informed_values(pomdp: TrustPOMDP, next_q: np.ndarray, accepting: np.ndarray, rejecting: np.ndarray,
                    horizon: int) -> np.ndarray:
    """A [horizon + 1, slots, n_x, n_trust, n_q]: A[k, s, x, θ, q] bounds from above the value of
    moving through successor slot s of road x from (θ, q) with k junctions left, for any policy
    (-inf where road x has no slot s; A[0] is never used). The relaxation behind it learns θ and q
    one junction late: each next slot is chosen on the junction's observation (h, e) and the
    previous (θ, q), not on the new θ (the fast informed bound of POMDPs). It is tighter than the
    relaxation that observes θ and q at once (relaxed_values), which it never exceeds; each
    backup adds RELAXATION_MARGIN so that rounding cannot take it below the true value."""
    n_x, n_t, n_q = pomdp.n_states, pomdp.n_trust, int(next_q.shape[0])
    successors = pomdp.successor_table
    slots = successors.shape[1]
    valid = successors >= 0                                              # [x, s]
    x2 = np.where(valid, successors, 0)
    weights = observation_and_trust(pomdp)[pomdp.road_incident[x2]]      # [x, s, h, e, θ, θ']
    has_next: np.ndarray = valid[x2]                                     # [x, s, s']: slot s' of x2
    goes_on = np.asarray(has_next.any(axis=2))                           # x2 has a successor
    table = np.full((horizon + 1, slots, n_x, n_t, n_q), -np.inf)
    done = accepted_on_arrival(accepting, next_q)                        # [q, x2, θ']
    # per observation, whether the new road's label accepts: the value with no junction after it,
    # and on a road without successors, where the drive ends
    arrived = np.einsum("xshetu,qxsu->xshetq", weights, done[:, x2, :])
    for k in range(1, horizon + 1):
        if k == 1:
            arrive = arrived.sum(axis=(2, 3))
        else:
            previous = np.where(np.isfinite(table[k - 1]), table[k - 1], 0.0)   # [s', x, θ, q]
            # max over the belief bits of the value at the DFA state they lead to: [s', q, x, θ']
            best = np.stack([over_bits(previous[b], next_q) for b in range(slots)])
            per_slot = np.einsum("xshetu,Sqxsu->xshetqS", weights, best[:, :, x2, :])
            per_slot = np.where(has_next[:, :, None, None, None, None, :], per_slot, -np.inf)
            chosen = per_slot.max(axis=6)                                # the next slot, on (h, e)
            chosen = np.where(goes_on[:, :, None, None, None, None], chosen, arrived)
            arrive = chosen.sum(axis=(2, 3))                             # [x, s, θ, q]
        value = np.minimum(1.0, arrive + RELAXATION_MARGIN)
        value[:, :, :, np.asarray(accepting, dtype=bool)] = 1.0
        value[:, :, :, np.asarray(rejecting, dtype=bool)] = 0.0
        table[k] = np.where(valid[:, :, None, None], value, -np.inf).transpose(1, 0, 2, 3)
    return table


LEAF_CHUNK = 16_384   # leaves valued at once (bounds the arrays of InformedLeaves.slot_values)


@dataclass(frozen=True, eq=False)
class InformedLeaves:
    """Upper bounds on the value of each successor slot at joint beliefs J over (θ, q), within a
    horizon: the slot's junction is chosen on J, the next one on J and that junction's observation
    (h, e), and from there on informed_values bounds the rest. Choosing both on J rather than on θ
    is what a policy can do, so these never exceed Σ J informed_values."""

    pomdp: TrustPOMDP
    weights: np.ndarray     # [n_incidents, h, e, θ, θ']: P(h, e, θ' | θ, incident)
    arrival: np.ndarray     # [n_q, n_x, θ']: accepted on arriving on the road, best belief bits
    best: np.ndarray        # [K + 1, slots, n_q, n_x, θ']: informed values, best belief bits (0: no slot)

    @classmethod
    def of(cls, pomdp: TrustPOMDP, next_q: np.ndarray, accepting: np.ndarray, rejecting: np.ndarray,
           horizon: int) -> InformedLeaves:
        table = informed_values(pomdp, next_q, accepting, rejecting, horizon)
        table = np.where(np.isfinite(table), table, 0.0)
        best = np.stack([np.stack([over_bits(slot, next_q) for slot in level]) for level in table])
        return cls(pomdp=pomdp, weights=observation_and_trust(pomdp),
                   arrival=accepted_on_arrival(accepting, next_q), best=best)

    def slot_values(self, x: np.ndarray, joint: np.ndarray, left: int) -> np.ndarray:
        """float [n, slots]: bounds on the value of each successor slot of roads x [n] at joint
        beliefs [n, n_trust, n_q] (live mass only) with `left` ≥ 1 junctions left (-inf where a road
        has no such slot)."""
        successors = self.pomdp.successor_table[np.asarray(x, dtype=np.int64)]
        out = np.full(successors.shape, -np.inf)
        for start in range(0, successors.shape[0], LEAF_CHUNK):
            part = slice(start, start + LEAF_CHUNK)
            out[part] = self._chunk(successors[part], joint[part], left)
        return out

    def _chunk(self, successors: np.ndarray, joint: np.ndarray, left: int) -> np.ndarray:
        out = np.full(successors.shape, -np.inf)
        for slot in range(successors.shape[1]):
            rows = np.flatnonzero(successors[:, slot] >= 0)
            incidents = self.pomdp.road_incident[successors[rows, slot]]
            for incident in np.unique(incidents):   # one shared P(h, e, θ' | θ) per incident kind
                these = rows[incidents == incident]
                out[these, slot] = self._arrivals(successors[these, slot], joint[these], incident, left)
        return out

    def _arrivals(self, x2: np.ndarray, joint: np.ndarray, incident: int, left: int) -> np.ndarray:
        """float [n]: the bound of moving to roads x2 [n] (all with `incident`) from joint beliefs."""
        n, n_t, n_q = x2.size, self.pomdp.n_trust, self.arrival.shape[0]
        # Σ_θ J(θ, q) P(h, e, θ' | θ, incident), the observation (h, e) as one axis o, as one matrix
        # product: [n, o, (q, θ')]
        weights = self.weights[incident].reshape(-1, n_t, n_t)
        n_o = weights.shape[0]
        mass = joint.transpose(0, 2, 1).reshape(n * n_q, n_t) @ weights.transpose(1, 0, 2).reshape(n_t, -1)
        mass = mass.reshape(n, n_q, n_o, n_t).transpose(0, 2, 1, 3).reshape(n, n_o, n_q * n_t)
        value = np.matmul(mass, self.arrival[:, x2, :].transpose(1, 0, 2).reshape(n, -1, 1))[:, :, 0]
        if left > 1:
            nexts = self.pomdp.successor_table[x2] >= 0                              # [n, slots']
            best = self.best[left - 1][:, :, x2, :].transpose(2, 1, 3, 0).reshape(n, n_q * n_t, -1)
            after = np.where(nexts[:, None, :], np.matmul(mass, best), -np.inf).max(axis=2)
            # a road without successors ends the drive there: what arriving on it accepted
            value = np.where(nexts.any(axis=1)[:, None], after, value)
        return value.sum(axis=1)


@dataclass(frozen=True, eq=False)
class RelaxedGuide:
    """The relaxation's action values at a joint belief: for each successor slot of road x,
    Σ_{θ, q} J(θ, q) Σ_θ' P(θ' | θ, inc(x')) max_bits R(x', θ', δ(q, L(x', θ', bits))), with R
    the relaxation's values for k junctions left after the move (horizon G: R[min(k, G)]; None:
    the unbounded values). The acting rule of joint policies off their stored nodes
    (policies/routing/trust_state_table.py)."""

    pomdp: TrustPOMDP
    best: np.ndarray            # [G + 1 or 1, n_q, n_x, n_trust]
    move: np.ndarray            # [n_incidents, n_trust, n_trust]
    horizon: int | None

    def action_values(self, x: np.ndarray, joint: np.ndarray, left: int) -> np.ndarray:
        """float [n, slots]: the values of the successor slots of roads x [n] at joint beliefs
        [n, n_trust, n_q] (-inf where a road has no such slot)."""
        k = 0 if self.horizon is None else min(max(left, 0), self.horizon)
        x = np.asarray(x, dtype=np.int64)
        successors = self.pomdp.successor_table[x]                     # [n, slots]
        out = np.full(successors.shape, -np.inf)
        best = self.best[k]                                             # [q, x, θ']
        for slot in range(successors.shape[1]):
            x2 = successors[:, slot]
            has = x2 >= 0
            if not has.any():
                continue
            rows, x2 = np.flatnonzero(has), x2[has]
            after = np.einsum("ntu,qnu->ntq", self.move[self.pomdp.road_incident[x2]], best[:, x2, :])
            out[rows, slot] = np.einsum("ntq,ntq->n", joint[rows], after)
        return out

    def greedy(self, x: np.ndarray, joint: np.ndarray, left: int) -> np.ndarray:
        """int [n]: the slot of the largest action value (the first on ties)."""
        return np.argmax(self.action_values(x, joint, left), axis=1)

    def policy_slots(self, t: int, x: np.ndarray, joint: np.ndarray) -> np.ndarray:
        """int [n]: the greedy slot at t junctions driven, k = horizon - t - 1 junctions left
        after the move (the full horizon once t reaches it). The joint policy's rule off its
        stored rows; the search expands its guided nodes with the very same call."""
        horizon = self.horizon
        left = horizon - t - 1 if horizon is not None and t < horizon else (horizon or 0)
        return self.greedy(x, joint, left)


def relaxed_guide(pomdp: TrustPOMDP, spec: Spec, horizon: int | None) -> RelaxedGuide:
    """The RelaxedGuide of `spec` for junction horizon `horizon` (None: unbounded)."""
    compiled = compile_spec(spec, pomdp.town)
    next_q = relaxed_next_q(pomdp, spec, compiled.dfa, compiled.labeller)    # [q, x, θ, bits]
    return guide_of(pomdp, next_q, relaxed_values(pomdp, spec, horizon), horizon)


def guide_of(pomdp: TrustPOMDP, next_q: np.ndarray, values: np.ndarray, horizon: int | None) -> RelaxedGuide:
    """The RelaxedGuide of the relaxation's values `values` (relaxed_values) and successor DFA
    states `next_q` (relaxed_next_q)."""
    tables = values[None] if horizon is None else values                      # [K, x, θ, q]
    best = np.stack([over_bits(table, next_q) for table in tables])           # [K, q, x, θ]
    move = trust_move(pomdp)
    return RelaxedGuide(pomdp=pomdp, best=best, move=move, horizon=horizon)
