"""Bounds on the value of the trust-free completion from a node, without the observation tree.

The trust-free completion (policies/routing/free.py) drives a road sequence fixed by (road x,
state-only task state p) alone, so from a node (x, q, p, b) with `steps` junctions left its value
is a forward computation along one road sequence. The exact computation is a tree over observation
sequences (beliefs after different sequences rarely coincide): exponential in the incident roads.
This module propagates probability mass over *clusters* of beliefs instead:

* Mass is exact. Along a fixed road sequence, P(o_1..o_k, θ_k) is the forward vector
  α_k = b W_{o_1} ... W_{o_k} (W_o = diag(P(o | θ)) T_o, the Bayes filter's matrix,
  policies/synthesis/belief_cells.py), and the belief after the sequence is α_k / Σ α_k. A
  cluster carries the sum of the α of its member sequences, so the probability of every event that
  is a union of clusters is exact, whatever was merged.
* Beliefs are enclosed. A cluster also carries a lower corner l: every member's belief lies in
  S(l) = {b in the simplex : b >= l}, a simplex with the n vertices l + (1 - Σ l) e_i. The filter
  step f_o(b) = b W_o / (b W_o 1) maps the hull of points into the hull of their images (vertices
  with P(o | v) = 0 drop out), so the componentwise minimum of the vertex images is a lower corner
  of the next cluster; merged clusters take the componentwise minimum of their corners.
* Labels are pessimistic where a cluster straddles a belief atom's hyperplane. When the atom values
  possible on S(l) (widened by the labeller's rounding margin) lead to different DFA states, the
  cluster's mass counts as failure for the lower bound and as success for the upper bound.
* Clusters are merged on (start node, DFA state, a grid cell of resolution δ of the belief); a start
  node with more than CLUSTER_CAP clusters has its δ multiplied by 4. Clusters lighter than
  MASS_FLOOR are dropped (failure for the lower bound, success for the upper bound).

So lower <= V_free <= upper for the exact-arithmetic Bayes process. Floating point: the corners are
lowered by CORNER_MARGIN at every step and the straddle test widened by the same, which covers the
one-step rounding of the filter (γ_{3n} relative, about 2e-15 for n = 7; labelling.py) with a
factor of several hundred; as for the suffix cells (belief_cells.LABEL_TOLERANCE) this covers the
accumulated error over a route by an argued margin, not a proof. The probabilities of a k-step
sequence under the vehicle's float filter and under α differ by at most a relative (1 + γ)^k, with
γ = γ_{4n+2}; the returned bounds are widened by that factor. Only for the Bayes rule (under the
authors' update the observation probabilities are not linear in a hidden-state vector).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trustroute.policies.logic.labelling import gamma, label_margin_factor
from trustroute.policies.model.product_mdp import ProductTables
from trustroute.policies.synthesis.belief_cells import LABEL_TOLERANCE, ObservationSymbols

CORNER_MARGIN = LABEL_TOLERANCE   # subtracted from every lower corner at every step
CLUSTER_CAP = 256                 # clusters per start node after a step's merge
INITIAL_RESOLUTION = 2.0 ** -16   # δ of the merge grid before any coarsening
MASS_FLOOR = 1e-13                # clusters lighter than this are dropped (bounded by the cap)


@dataclass(frozen=True)
class CompletionBounds:
    """lower[i] <= value of the trust-free completion from start i <= upper[i].

    straddle[i]: mass dropped at clusters straddling a threshold or too light (upper - lower before
    the rounding widening); clusters: largest number of clusters held at once.
    """

    lower: np.ndarray
    upper: np.ndarray
    straddle: np.ndarray
    clusters: int


@dataclass(frozen=True, eq=False)
class FreeRoute:
    """The trust-free completion's move as arrays: next road and next task state per (x, p)."""

    next_road: np.ndarray     # [n_x, n_p]
    next_task: np.ndarray     # [n_x, n_p]

    @staticmethod
    def build(tables: ProductTables, free_slot: np.ndarray, next_p: np.ndarray) -> FreeRoute:
        n_x = tables.n_x
        road = tables.successors[np.arange(n_x)[:, None], free_slot]
        road = np.where(road >= 0, road, tables.successors[:, :1])
        return FreeRoute(next_road=road, next_task=next_p[np.arange(next_p.shape[0])[None, :], road])


def _outcome_table(symbols: ObservationSymbols) -> np.ndarray:
    width = max(len(s) for s in symbols.by_incident)
    table = np.full((len(symbols.by_incident), width), -1, dtype=np.int64)
    for i, members in enumerate(symbols.by_incident):
        table[i, : len(members)] = members
    return table


def completion_bounds(tables: ProductTables, symbols: ObservationSymbols, route: FreeRoute,
                      x: np.ndarray, q: np.ndarray, p: np.ndarray, belief: np.ndarray,
                      steps: np.ndarray) -> CompletionBounds:
    """Bounds on P(the DFA accepts within `steps` junctions | trust-free completion from (x, q, p, b)),
    for each start i; DFA state q is the state after reading the current road."""
    if symbols.rule != "bayes":
        raise ValueError("cluster bounds need the Bayes rule (observation mass linear in α)")
    x = np.asarray(x, dtype=np.int64).copy()
    p = np.asarray(p, dtype=np.int64).copy()
    steps = np.asarray(steps, dtype=np.int64).copy()
    steps0 = steps.copy()
    if x.size >= 2 ** 20 or tables.n_q >= 2 ** 12:
        raise ValueError("at most 2**20 start nodes and 2**12 DFA states per call (merge key)")
    n_start = x.size
    n = symbols.likelihood.shape[1]
    outcomes = _outcome_table(symbols)
    incident_of = tables.pomdp.road_incident
    accepted = np.zeros(n_start)
    straddle = np.zeros(n_start)
    resolution = np.full(n_start, INITIAL_RESOLUTION)
    coeffs, offsets = tables.belief_coeffs, tables.belief_offsets       # [m, n], [m]
    m = offsets.size
    margin = label_margin_factor(n) * np.abs(coeffs).sum(axis=1) + CORNER_MARGIN  # [m]
    c_min, c_max = coeffs.min(axis=1, initial=0.0), coeffs.max(axis=1, initial=0.0)
    bit_values = (np.arange(2 ** m)[:, None] >> np.arange(m)[None, :]) & 1      # [bits, m]

    q = np.asarray(q, dtype=np.int64)
    owner = np.arange(n_start)
    state = q.copy()
    alpha = np.asarray(belief, dtype=float).copy()
    corner = np.maximum(alpha - CORNER_MARGIN, 0.0)
    done = tables.accepting[state]
    accepted[done] = 1.0
    keep = ~done & ~tables.rejecting[state] & (steps > 0)
    owner, state, alpha, corner = owner[keep], state[keep], alpha[keep], corner[keep]
    most = owner.size
    while owner.size:
        road = route.next_road[x, p]                     # per start
        task = route.next_task[x, p]
        x2 = road[owner]
        incident = incident_of[x2]
        parts = []
        for j in range(outcomes.shape[1]):
            symbol = outcomes[incident, j]
            ok = symbol >= 0
            if not ok.any():
                continue
            w = symbols.update[symbol[ok]]                               # [r, n, n]
            a2 = np.einsum("rk,rkl->rl", alpha[ok], w)
            mass = a2.sum(axis=1)
            lo = corner[ok]
            spread = np.maximum(1.0 - lo.sum(axis=1), 0.0)
            # images of the vertices lo + spread e_i: lo W + spread W_i
            image = np.einsum("rk,rkl->rl", lo, w)[:, None, :] + spread[:, None, None] * w
            total = image.sum(axis=2)
            valid = total > 0
            normalised = np.divide(image, total[:, :, None], out=np.zeros_like(image),
                                   where=valid[:, :, None])
            lo2 = np.where(valid[:, :, None], normalised, np.inf).min(axis=1)
            lo2 = np.where(np.isfinite(lo2), np.maximum(lo2 - CORNER_MARGIN, 0.0), 0.0)
            spread2 = np.maximum(1.0 - lo2.sum(axis=1), 0.0)
            o_owner, o_state, o_road = owner[ok], state[ok], x2[ok]
            # DFA successors over the atom values possible on S(lo2)
            if m:
                base = lo2 @ coeffs.T                                     # [r, m]
                low = base + spread2[:, None] * c_min[None, :]
                high = base + spread2[:, None] * c_max[None, :]
                can_true = high > offsets[None, :] - margin[None, :]
                can_false = low <= offsets[None, :] + margin[None, :]
                fits = np.where(bit_values[None, :, :] == 1, can_true[:, None, :],
                                can_false[:, None, :]).all(axis=2)       # [r, bits]
                successor = tables.next_q[o_state[:, None], o_road[:, None], np.arange(2 ** m)[None, :]]
                first = np.where(fits, successor, np.iinfo(np.int64).max).min(axis=1)
                last = np.where(fits, successor, -1).max(axis=1)
                ambiguous = first != last
                q2 = first
            else:
                q2 = tables.next_q[o_state, o_road, 0]
                ambiguous = np.zeros(q2.size, dtype=bool)
            light = mass < MASS_FLOOR
            np.add.at(straddle, o_owner[ambiguous | (light & ~tables.rejecting[q2])],
                      mass[ambiguous | (light & ~tables.rejecting[q2])])
            settled = ~ambiguous & ~light
            hit = settled & tables.accepting[q2]
            np.add.at(accepted, o_owner[hit], mass[hit])
            go_on = settled & ~tables.accepting[q2] & ~tables.rejecting[q2]
            parts.append((o_owner[go_on], q2[go_on], a2[go_on], lo2[go_on]))
        x, p, steps = road, task, steps - 1
        owner = np.concatenate([part[0] for part in parts])
        state = np.concatenate([part[1] for part in parts])
        alpha = np.concatenate([part[2] for part in parts])
        corner = np.concatenate([part[3] for part in parts])
        live = steps[owner] > 0
        owner, state, alpha, corner = owner[live], state[live], alpha[live], corner[live]
        owner, state, alpha, corner = _merge(owner, state, alpha, corner, resolution)
        most = max(most, owner.size)
    # Rounding: each start's sequences have at most steps0 factors of (1 + γ_{4n+2}) between the
    # vehicle's float probabilities and α; the sums add at most `most` terms per step and outcome.
    rounds = (4 * n + 2) * steps0 + most * steps0 * outcomes.shape[1]
    widen = np.array([gamma(int(k)) for k in np.maximum(rounds, 1)])
    lower = np.maximum(accepted * (1.0 - widen), 0.0)
    upper = np.minimum((accepted + straddle) * (1.0 + widen), 1.0)
    return CompletionBounds(lower=lower, upper=upper, straddle=straddle, clusters=int(most))


def _merge(owner: np.ndarray, state: np.ndarray, alpha: np.ndarray, corner: np.ndarray,
           resolution: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Merge clusters in the same (owner, DFA state, grid cell); coarsen owners over CLUSTER_CAP.

    The key is (owner: 20 bits, DFA state: 12 bits, a 32-bit hash of the cell): a hash collision
    merges two cells of the same owner and DFA state, which is as sound as any merge (only looser)."""
    n = corner.shape[1]
    multipliers = (np.arange(1, n + 2, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)) | np.uint64(1)
    while owner.size:
        spread = np.maximum(1.0 - corner.sum(axis=1), 0.0)
        centre = corner + spread[:, None] / n
        cell = np.floor(centre / resolution[owner][:, None]).astype(np.int64).astype(np.uint64)
        mixed = (cell * multipliers[None, :n]).sum(axis=1)
        key = ((owner.astype(np.uint64) << np.uint64(44)) | (state.astype(np.uint64) << np.uint64(32))
               | (mixed >> np.uint64(32)))
        order = np.argsort(key)
        key = key[order]
        starts = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))
        owner, state = owner[order][starts], state[order][starts]
        alpha = np.add.reduceat(alpha[order], starts, axis=0)
        corner = np.minimum.reduceat(corner[order], starts, axis=0)
        counts = np.bincount(owner, minlength=resolution.size)
        crowded = counts > CLUSTER_CAP
        if not crowded.any():
            break
        resolution[crowded] *= 4.0
    return owner, state, alpha, corner
