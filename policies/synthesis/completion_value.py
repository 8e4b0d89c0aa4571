"""Bounds on the value of the trust-free completion from a node, without the observation tree.

The free completion (policies/routing/free.py, `free_completion`: the trust-free completion of the
state-only task, then the shortest route back to what the DFA still needs) drives a road fixed by
(road x, DFA state q, state-only task state p), never by the belief, so from a node (x, q, p, b)
with `steps` junctions left its value is a forward computation along road sequences that branch
only where the DFA state does. The exact computation is a tree over observation
sequences (beliefs after different sequences rarely coincide): exponential in the incident roads.
This module propagates probability mass over *clusters* of beliefs instead:

* Mass is exact. Along a fixed road sequence, P(o_1..o_k, θ_k) is the forward vector
  α_k = b W_{o_1} ... W_{o_k} (W_o = diag(P(o | θ)) T_o, the Bayes filter's matrix,
  policies/synthesis/belief_cells.py), and the belief after the sequence is α_k / Σ α_k. A
  cluster carries the sum of the α of its member sequences, so the probability of every event that
  is a union of clusters is exact, whatever was merged.
* Beliefs are enclosed. A cluster carries n vertex beliefs whose hull contains every member's
  belief. The filter step f_o(b) = b W_o / (b W_o 1) maps the hull of points onto the hull of their
  images (vertices with P(o | v) = 0 drop out), so the vertex images enclose the next beliefs with
  no loss. A merged cluster is enclosed by the simplex {b >= l} (vertices l + (1 - Σ l) e_i), l the
  componentwise minimum of the members' vertices lowered by CORNER_MARGIN.
* Labels are pessimistic where a cluster straddles a belief atom's hyperplane. When the atom values
  possible on the hull of its vertices (widened by the labeller's rounding margin) lead to
  different DFA states, the cluster's mass counts as failure for the lower bound and as success
  for the upper bound.
* Clusters are merged on (start node, road, task state, DFA state, a grid cell of side δ of the
  vertices' mean); a start node with more than CLUSTER_CAP clusters has its δ doubled until it has
  at most that many. Clusters lighter than MASS_FLOOR are dropped (failure for the lower bound,
  success for the upper bound). The move may depend on the DFA state (FreeRoute is indexed by
  (x, q, p)): each cluster has one DFA state, so it takes one move.

So lower <= V_free <= upper for the exact-arithmetic Bayes process. Floating point: the vertices
are float images of float vertices, as the suffix cells' are (belief_cells.py), and the straddle
test is widened by CORNER_MARGIN besides the labeller's rounding margin; that covers the one-step
rounding of the filter (γ_{3n} relative, about 2e-15 for n = 7; labelling.py) by a factor of several
hundred, and, as for the suffix cells (belief_cells.LABEL_TOLERANCE), the accumulated error over a
route by an argued margin, not a proof. The probabilities of a k-step sequence under the vehicle's
float filter and under α differ by at most a relative (1 + γ)^k, with γ = γ_{4n+2}; the returned
bounds are widened by that factor (and by the rounding of the sums). Only for the Bayes rule (under
the authors' update the observation probabilities are not linear in a hidden-state vector).
"""

from __future__ import annotations

import time
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

    straddle[i]: mass dropped at clusters straddling a threshold or too light, or still in flight
    when the deadline stopped the propagation (upper - lower before the rounding widening);
    clusters: largest number of clusters held at once; interrupted: stopped by the deadline.
    """

    lower: np.ndarray
    upper: np.ndarray
    straddle: np.ndarray
    clusters: int
    interrupted: bool = False


@dataclass(frozen=True, eq=False)
class FreeRoute:
    """A completion's move as arrays: next road and next task state per (x, q, p).

    The move may depend on the DFA state q (which follows the labels) but not on the belief."""

    next_road: np.ndarray     # [n_x, n_q, n_p]
    next_task: np.ndarray     # [n_x, n_q, n_p]

    @staticmethod
    def build(tables: ProductTables, slot: np.ndarray, next_p: np.ndarray) -> FreeRoute:
        """slot [n_x, n_p] (the trust-free completion, the same for every q) or [n_x, n_q, n_p]."""
        n_x, n_q = tables.n_x, tables.n_q
        if slot.ndim == 2:
            slot = np.broadcast_to(slot[:, None, :], (n_x, n_q, slot.shape[1]))
        road = tables.successors[np.arange(n_x)[:, None, None], slot]
        road = np.where(road >= 0, road, tables.successors[:, :1, None])
        task = next_p[np.arange(next_p.shape[0])[None, None, :], road]
        return FreeRoute(next_road=road, next_task=task)


def _outcome_table(symbols: ObservationSymbols) -> np.ndarray:
    width = max(len(s) for s in symbols.by_incident)
    table = np.full((len(symbols.by_incident), width), -1, dtype=np.int64)
    for i, members in enumerate(symbols.by_incident):
        table[i, : len(members)] = members
    return table


def completion_bounds(tables: ProductTables, symbols: ObservationSymbols, route: FreeRoute,
                      x: np.ndarray, q: np.ndarray, p: np.ndarray, belief: np.ndarray,
                      steps: np.ndarray, deadline: float | None = None) -> CompletionBounds:
    """Bounds on P(the DFA accepts within `steps` junctions | trust-free completion from (x, q, p, b)),
    for each start i; DFA state q is the state after reading the current road.

    deadline (time.perf_counter() seconds): the propagation stops there, junction step by junction
    step; the mass still in flight then counts to the upper bound only (`interrupted` is True), so
    both bounds stay sound, only looser."""
    if symbols.rule != "bayes":
        raise ValueError("cluster bounds need the Bayes rule (observation mass linear in α)")
    x = np.asarray(x, dtype=np.int64).copy()
    p = np.asarray(p, dtype=np.int64).copy()
    steps = np.asarray(steps, dtype=np.int64).copy()
    steps0 = steps.copy()
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
    bit_values = (np.arange(2 ** m)[:, None] >> np.arange(m)[None, :]) & 1      # [bits, m]

    q = np.asarray(q, dtype=np.int64)
    owner = np.arange(n_start)
    state = q.copy()
    alpha = np.asarray(belief, dtype=float).copy()
    corner = np.repeat(alpha[:, None, :], n, axis=1)      # vertices of the enclosure [r, n, n]
    done = tables.accepting[state]
    accepted[done] = 1.0
    keep = ~done & ~tables.rejecting[state] & (steps > 0)
    owner, state, alpha, corner, x, p = (a[keep] for a in (owner, state, alpha, corner, x, p))
    most = owner.size
    interrupted = False
    while owner.size:
        if deadline is not None and time.perf_counter() >= deadline:
            # the sequences still followed may yet accept: all their mass to the upper bound
            np.add.at(straddle, owner, alpha.sum(axis=1))
            interrupted = True
            break
        x2 = route.next_road[x, state, p]                # per cluster: x, p and q
        p2 = route.next_task[x, state, p]
        incident = incident_of[x2]
        parts = []
        for j in range(outcomes.shape[1]):
            symbol = outcomes[incident, j]
            ok = symbol >= 0
            if not ok.any():
                continue
            rows = np.flatnonzero(ok)
            a2 = np.empty((rows.size, n))
            image = np.empty((rows.size, n, n))
            for o in np.unique(symbol[rows]).tolist():   # one matrix product per symbol
                here = symbol[rows] == o
                a2[here] = alpha[rows[here]] @ symbols.update[o]
                image[here] = corner[rows[here]] @ symbols.update[o]
            mass = a2.sum(axis=1)
            # the hull of the vertex images contains the image of the hull (vertices with
            # P(o | v) = 0 drop out: they are replaced by a valid one of the same cluster)
            total = image.sum(axis=2)
            valid = total > 0
            normalised = np.divide(image, total[:, :, None], out=np.zeros_like(image),
                                   where=valid[:, :, None])
            some = valid.argmax(axis=1)
            lo2 = np.where(valid[:, :, None], normalised,
                           normalised[np.arange(some.size), some][:, None, :])
            o_owner, o_state, o_road, o_task = owner[ok], state[ok], x2[ok], p2[ok]
            # DFA successors over the atom values possible on S(lo2)
            if m:
                at_vertices = lo2 @ coeffs.T                              # [r, v, m]
                low, high = at_vertices.min(axis=1), at_vertices.max(axis=1)
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
            unsettled = ambiguous | (light & ~tables.rejecting[q2])   # may yet accept: upper only
            np.add.at(straddle, o_owner[unsettled], mass[unsettled])
            settled = ~ambiguous & ~light
            hit = settled & tables.accepting[q2]
            np.add.at(accepted, o_owner[hit], mass[hit])
            go_on = settled & ~tables.accepting[q2] & ~tables.rejecting[q2]
            parts.append((o_owner[go_on], q2[go_on], a2[go_on], lo2[go_on], o_road[go_on],
                          o_task[go_on]))
        steps = steps - 1
        owner, state, alpha, corner, x, p = (np.concatenate([part[k] for part in parts])
                                             for k in range(6))
        live = steps[owner] > 0
        owner, state, alpha, corner, x, p = (a[live] for a in (owner, state, alpha, corner, x, p))
        owner, state, alpha, corner, x, p = _merge(owner, state, alpha, corner, x, p, resolution,
                                                   tables.n_x, tables.n_q)
        most = max(most, owner.size)
    # Rounding: each start's sequences have at most steps0 factors of (1 + γ_{4n+2}) between the
    # vehicle's float probabilities and α; the sums add at most `most` terms per step and outcome.
    rounds = (4 * n + 2) * steps0 + most * steps0 * outcomes.shape[1]
    widen = np.array([gamma(int(k)) for k in np.maximum(rounds, 1)])
    lower = np.maximum(accepted * (1.0 - widen), 0.0)
    upper = np.minimum((accepted + straddle) * (1.0 + widen), 1.0)
    return CompletionBounds(lower=lower, upper=upper, straddle=straddle, clusters=int(most),
                            interrupted=interrupted)


def _merge(owner: np.ndarray, state: np.ndarray, alpha: np.ndarray, vertices: np.ndarray,
           x: np.ndarray, p: np.ndarray, resolution: np.ndarray, n_x: int, n_q: int
           ) -> tuple[np.ndarray, ...]:
    """Merge clusters in the same (owner, road, task state, DFA state, grid cell of the vertices'
    mean); coarsen owners over CLUSTER_CAP. A merged cluster's enclosure is the simplex
    {b >= l} with l the componentwise minimum of every member vertex, lowered by CORNER_MARGIN;
    a cluster alone in its cell keeps its vertices.

    (owner, x, p, q) is packed exactly into one integer; the cell is a 64-bit hash: a collision
    merges two cells of the same (owner, x, p, q), which is as sound as any merge (only looser)."""
    n = vertices.shape[2]
    if owner.size == 0:
        return owner, state, alpha, vertices, x, p
    multipliers = (np.arange(1, n + 1, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)) | np.uint64(1)
    n_p = int(p.max(initial=0)) + 1
    place = ((owner * n_x + x) * n_p + p) * n_q + state
    centre = vertices.mean(axis=1)
    while True:     # the finest grid per owner (doubling δ) with at most CLUSTER_CAP cells
        cell = np.floor(centre / resolution[owner][:, None]).astype(np.int64).astype(np.uint64)
        mixed = (cell * multipliers[None, :]).sum(axis=1)
        order = np.lexsort((mixed, place))
        a, b = place[order], mixed[order]
        first = np.concatenate([[True], (a[1:] != a[:-1]) | (b[1:] != b[:-1])])
        counts = np.bincount(owner[order][first], minlength=resolution.size)
        crowded = counts > CLUSTER_CAP
        if not crowded.any():
            break
        resolution[crowded] *= 2.0
    starts = np.flatnonzero(first)
    size = np.diff(np.append(starts, order.size))
    pick = order[starts]
    merged = vertices[pick]
    several = size > 1
    if several.any():
        corner = np.minimum.reduceat(vertices[order].min(axis=1), starts, axis=0)[several]
        corner = np.maximum(corner - CORNER_MARGIN, 0.0)
        spread = np.maximum(1.0 - corner.sum(axis=1), 0.0)
        merged[several] = corner[:, None, :] + spread[:, None, None] * np.eye(n)[None]
    alpha = np.add.reduceat(alpha[order], starts, axis=0)
    owner, state, x, p, vertices = owner[pick], state[pick], x[pick], p[pick], merged
    return owner, state, alpha, vertices, x, p
