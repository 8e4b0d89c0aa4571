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
* Beliefs are enclosed. A cluster carries a box [lo, hi] whose intersection with the simplex,
  B = {b : lo <= b <= hi, Σ b = 1}, contains every member's belief (a cluster that never merged has
  lo = hi = its belief). The filter step f_o(b) = b W_o / (b W_o 1) is linear-fractional, so each
  coordinate of f_o over B attains its extremes at a vertex of B, and at the vertex a greedy fill
  reaches: R_j(b) = (b·a)/(b·d) (a = W_o[:, j], d = W_o 1) has its maximum λ* where
  max_B (a - λ* d)·b = 0, and a linear function is maximised over B by filling 1 - Σ lo into the
  coordinates in decreasing order of (a - λ* d)_i, each up to hi_i - lo_i. That order changes
  only where two lines a_i - λ d_i cross, so the orders of every λ interval (`fill_orders`, fixed
  per symbol and coordinate: `ObservationSymbols.fill_orders`, policies/synthesis/belief_cells.py)
  contain the optimal one. Dinkelbach's iteration (λ <- R_j of the
  greedy vertex of λ, until a vertex repeats) finds it in a few fills; where it does not settle,
  every such order is tried. So the next box is the exact range of f_o over B per coordinate
  (the minimum with the reversed orders), widened by CORNER_MARGIN. Merging takes
  the box hull (componentwise min of lo, max of hi), widened the same way. The range of an atom's
  affine function over B is a greedy fill too (`linear_range`).
* Labels are pessimistic where a cluster straddles a belief atom's hyperplane. When the atom values
  possible on B (widened by the labeller's rounding margin) lead to
  different DFA states, the cluster's mass counts as failure for the lower bound and as success
  for the upper bound.
* Clusters are merged on (start node, road, task state, DFA state, a grid cell of side δ of the
  box's centre); a start node with more than CLUSTER_CAP clusters has its δ doubled until it has
  at most that many. Clusters lighter than MASS_FLOOR are dropped (failure for the lower bound,
  success for the upper bound). The move may depend on the DFA state (FreeRoute is indexed by
  (x, q, p)): each cluster has one DFA state, so it takes one move.

So lower <= V_free <= upper for the exact-arithmetic Bayes process. Floating point: the boxes are
float images of float boxes, as the suffix cells' vertices are (belief_cells.py): each image and
each merge is widened by CORNER_MARGIN, and the straddle test by CORNER_MARGIN besides the
labeller's rounding margin; that covers the one-step
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
from typing import NamedTuple

import numpy as np

from trustroute.policies.belief.product_mdp import ProductTables
from trustroute.policies.logic.labelling import gamma, label_margin_factor
from trustroute.policies.synthesis.belief_cells import LABEL_TOLERANCE, ObservationSymbols
from trustroute.policies.work_clock import now as clock_now
from trustroute.policies.work_clock import spend

CORNER_MARGIN = LABEL_TOLERANCE   # every box image and merge is widened by this
CLUSTER_CAP = 64                  # clusters per start node after a step's merge
INITIAL_RESOLUTION = 2.0 ** -16   # δ of the merge grid before any coarsening
DINKELBACH_STEPS = 6               # iterations before the exhaustive greedy vertices
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
class CompletionStarts:
    """The nodes a completion is valued from, one per start i: road x, DFA state q after reading
    it, state-only task state p, the AV's belief [n, n_trust] and the junctions left (`steps`)."""

    x: np.ndarray
    q: np.ndarray
    p: np.ndarray
    belief: np.ndarray
    steps: np.ndarray


class _Clusters(NamedTuple):
    """Clusters in flight, one row each: the start they came from (owner), their DFA state, the
    sum α of their sequences' forward vectors [r, n], their box [lo, hi] [r, n], road x and task
    state p."""

    owner: np.ndarray
    state: np.ndarray
    alpha: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    x: np.ndarray
    p: np.ndarray


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


def greedy_vertices(lo: np.ndarray, hi: np.ndarray, orders: np.ndarray) -> np.ndarray:
    """[r, k, n]: for each box (lo, hi [r, n]) and order [k, n] shared by every box, the point of
    {lo <= b <= hi, Σb = 1} that fills 1 - Σ lo into the coordinates in that order, each up to
    hi - lo."""
    return ordered_fill(lo, hi, np.broadcast_to(orders[None], (lo.shape[0],) + orders.shape))


def linear_range(lo: np.ndarray, hi: np.ndarray, coeffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) of coeffs·b over each box-simplex {lo <= b <= hi, Σb = 1}: the greedy fills in
    increasing and decreasing coefficient order."""
    order = np.argsort(-coeffs, kind="stable")
    ends = greedy_vertices(lo, hi, np.stack([order, order[::-1]])) @ coeffs      # [r, 2]
    return ends[:, 1], ends[:, 0]


def ordered_fill(lo: np.ndarray, hi: np.ndarray, order: np.ndarray) -> np.ndarray:
    """[r, J, n]: the greedy fill of each box (lo, hi [r, n]) in each of its orders [r, J, n]."""
    room = np.take_along_axis(np.broadcast_to((hi - lo)[:, None, :], order.shape), order, axis=2)
    rest = np.maximum(1.0 - lo.sum(axis=1), 0.0)[:, None, None]
    added = np.clip(rest - (np.cumsum(room, axis=2) - room), 0.0, room)
    filled = np.empty_like(added)
    np.put_along_axis(filled, order, added, axis=2)
    return lo[:, None, :] + filled


def _fractional_extremes(lo: np.ndarray, hi: np.ndarray, update: np.ndarray, likelihood: np.ndarray,
                         start: np.ndarray, sign: float) -> tuple[np.ndarray, np.ndarray]:
    """Dinkelbach's iteration for the maximum (sign 1) or minimum (sign -1) of every coordinate
    R_j(b) = (b·W[:, j]) / (b·d) over each box-simplex, from the guesses `start` [r, n]: the greedy
    vertex of the current λ gives the next λ = R_j(vertex); once a vertex repeats, λ is the extreme
    (max_B (a - λ d)·b = 0 at it). Returns (value, settled) [r, n]; rows not settled within
    DINKELBACH_STEPS, or whose vertex has P(o | v) = 0, are left to the caller."""
    value = start.copy()
    settled = np.zeros(value.shape, dtype=bool)
    rows = np.arange(value.shape[0])          # rows still iterating (settled rows keep their vertex)
    previous = None
    for _ in range(DINKELBACH_STEPS):
        score = sign * (update.T[None, :, :] - value[rows][:, :, None] * likelihood[None, None, :])
        vertex = ordered_fill(lo[rows], hi[rows], np.argsort(-score, axis=2, kind="stable"))
        denominator = vertex @ likelihood                                                  # [r, J]
        numerator = np.einsum("rjn,nj->rj", vertex, update)
        valid = denominator > 0
        ratio = numerator / np.where(valid, denominator, 1.0)
        done = (valid & (vertex == previous).all(axis=2)) if previous is not None else np.zeros_like(valid)
        value[rows] = np.where(valid, ratio, value[rows])
        settled[rows] = done
        # a row is dropped once all its coordinates settled: iterating further repeats the vertex
        going = ~done.all(axis=1)
        if not going.any():
            break
        rows, previous = rows[going], vertex[going]
    return value, settled


def box_image(lo: np.ndarray, hi: np.ndarray, symbols: ObservationSymbols, o: int
              ) -> tuple[np.ndarray, np.ndarray]:
    """A box enclosing f_o(B) for each box-simplex B = {lo <= b <= hi, Σb = 1} (rows): per coordinate
    the extremes of the linear-fractional map (Dinkelbach's iteration from the centre's image, or
    where that does not settle, every greedy vertex of `fill_orders`), widened by CORNER_MARGIN.
    Boxes that are points (lo = hi) map to the point's image. Where a candidate vertex has
    P(o | v) = 0 the coordinate falls back to the range of T_o[i, j] over the trust levels the box
    allows (f_o(b)_j is a weighted mean of those), which is sound but looser."""
    update = symbols.update[o]
    likelihood = update.sum(axis=1)
    point = (hi == lo).all(axis=1)
    image = lo[point] @ update
    total = image.sum(axis=1, keepdims=True)
    out_lo = np.empty_like(lo)
    out_hi = np.empty_like(hi)
    out_lo[point] = out_hi[point] = np.divide(image, total, out=np.zeros_like(image), where=total > 0)
    boxes = np.flatnonzero(~point)
    if boxes.size == 0:
        return out_lo, out_hi
    blo, bhi = lo[boxes], hi[boxes]
    transition = np.divide(update, likelihood[:, None], out=np.zeros_like(update),
                           where=likelihood[:, None] > 0)
    allowed = (bhi > 0) & (likelihood > 0)[None, :]                      # [r, n]
    mean_lo = np.where(allowed[:, :, None], transition[None], np.inf).min(axis=1)      # [r, n]
    mean_hi = np.where(allowed[:, :, None], transition[None], -np.inf).max(axis=1)
    centre = 0.5 * (blo + bhi) @ update
    centre /= np.maximum(centre.sum(axis=1, keepdims=True), np.finfo(float).tiny)
    high, high_settled = _fractional_extremes(blo, bhi, update, likelihood, centre, 1.0)
    low, low_settled = _fractional_extremes(blo, bhi, update, likelihood, centre, -1.0)
    rows, columns = np.nonzero(~(high_settled & low_settled))
    for j in np.unique(columns).tolist():
        which = rows[columns == j]
        orders = symbols.fill_orders[o][j]
        tops = greedy_vertices(blo[which], bhi[which], orders)
        bottoms = greedy_vertices(blo[which], bhi[which], orders[:, ::-1])
        top_den, bottom_den = tops @ likelihood, bottoms @ likelihood
        valid = (top_den > 0).all(axis=1) & (bottom_den > 0).all(axis=1)
        top = ((tops @ update[:, j]) / np.where(top_den > 0, top_den, 1.0)).max(axis=1)
        bottom = ((bottoms @ update[:, j]) / np.where(bottom_den > 0, bottom_den, 1.0)).min(axis=1)
        high[which, j] = np.where(valid, top, np.inf)
        low[which, j] = np.where(valid, bottom, -np.inf)
    out_lo[boxes] = np.maximum(np.maximum(low, mean_lo) - CORNER_MARGIN, 0.0)
    out_hi[boxes] = np.minimum(np.minimum(high, mean_hi) + CORNER_MARGIN, 1.0)
    return out_lo, out_hi


def outcome_table(symbols: ObservationSymbols) -> np.ndarray:
    width = max(len(s) for s in symbols.by_incident)
    table = np.full((len(symbols.by_incident), width), -1, dtype=np.int64)
    for i, members in enumerate(symbols.by_incident):
        table[i, : len(members)] = members
    return table


def completion_bounds(tables: ProductTables, symbols: ObservationSymbols, route: FreeRoute,
                      starts: CompletionStarts, deadline: float | None = None) -> CompletionBounds:
    """Bounds on P(the DFA accepts within `steps` junctions | trust-free completion from (x, q, p, b)),
    for each start i of `starts`; DFA state q is the state after reading the current road.

    deadline (a time on the synthesis' clock, policies/work_clock.py): the propagation stops there,
    junction step by junction step; the mass still in flight then counts to the upper bound only
    (`interrupted` is True), so both bounds stay sound, only looser."""
    if symbols.rule != "bayes":
        raise ValueError("cluster bounds need the Bayes rule (observation mass linear in α)")
    x = np.asarray(starts.x, dtype=np.int64).copy()
    p = np.asarray(starts.p, dtype=np.int64).copy()
    steps = np.asarray(starts.steps, dtype=np.int64).copy()
    steps0 = steps.copy()
    n_start = x.size
    n = symbols.likelihood.shape[1]
    outcomes = outcome_table(symbols)
    incident_of = tables.pomdp.road_incident
    accepted = np.zeros(n_start)
    straddle = np.zeros(n_start)
    resolution = np.full(n_start, INITIAL_RESOLUTION)
    coeffs, offsets = tables.belief_coeffs, tables.belief_offsets       # [m, n], [m]
    m = offsets.size
    margin = label_margin_factor(n) * np.abs(coeffs).sum(axis=1) + CORNER_MARGIN  # [m]
    bit_values = (np.arange(2 ** m)[:, None] >> np.arange(m)[None, :]) & 1      # [bits, m]

    q = np.asarray(starts.q, dtype=np.int64)
    owner = np.arange(n_start)
    state = q.copy()
    alpha = np.asarray(starts.belief, dtype=float).copy()
    lo = alpha.copy()                                    # the enclosing box [r, n]: lo, hi
    hi = alpha.copy()
    done = tables.accepting[state]
    accepted[done] = 1.0
    keep = ~done & ~tables.rejecting[state] & (steps > 0)
    owner, state, alpha, lo, hi, x, p = (a[keep] for a in (owner, state, alpha, lo, hi, x, p))
    most = owner.size
    interrupted = False
    while owner.size:
        # (the wall clock read through this module's `time`, which a caller may replace)
        if deadline is not None and clock_now(time.perf_counter) >= deadline:
            # the sequences still followed may yet accept: all their mass to the upper bound
            np.add.at(straddle, owner, alpha.sum(axis=1))
            interrupted = True
            break
        spend(owner.size)
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
            lo2 = np.empty((rows.size, n))
            hi2 = np.empty((rows.size, n))
            for o in np.unique(symbol[rows]).tolist():   # one matrix product per symbol
                here = symbol[rows] == o
                a2[here] = alpha[rows[here]] @ symbols.update[o]
                lo2[here], hi2[here] = box_image(lo[rows[here]], hi[rows[here]], symbols, o)
            mass = a2.sum(axis=1)
            o_owner, o_state, o_road, o_task = owner[ok], state[ok], x2[ok], p2[ok]
            # DFA successors over the atom values possible on the box
            if m:
                ranges = [linear_range(lo2, hi2, coeffs[k]) for k in range(m)]
                low = np.stack([r[0] for r in ranges], axis=1)                 # [r, m]
                high = np.stack([r[1] for r in ranges], axis=1)
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
            parts.append((o_owner[go_on], q2[go_on], a2[go_on], lo2[go_on], hi2[go_on], o_road[go_on],
                          o_task[go_on]))
        steps = steps - 1
        owner, state, alpha, lo, hi, x, p = (np.concatenate([part[k] for part in parts])
                                             for k in range(7))
        live = steps[owner] > 0
        owner, state, alpha, lo, hi, x, p = (a[live] for a in (owner, state, alpha, lo, hi, x, p))
        owner, state, alpha, lo, hi, x, p = _merge(_Clusters(owner, state, alpha, lo, hi, x, p), resolution,
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


def grid_merge(place: np.ndarray, group: np.ndarray, features: np.ndarray, resolution: np.ndarray,
               cap: int) -> tuple[np.ndarray, np.ndarray]:
    """The merge grid: items in the same `place` and the same cell of side resolution[group] of
    their `features` merge, δ doubled (in place, in `resolution`) for every group with more than
    `cap` cells until none has. Returns (order: the items sorted by place and cell, first: True
    where a cell begins in that order). The cell is a 64-bit hash of its coordinates: a collision
    merges two cells of one place, which is as sound as any merge (only looser)."""
    multipliers = (np.arange(1, features.shape[1] + 1, dtype=np.uint64)
                   * np.uint64(0x9E3779B97F4A7C15)) | np.uint64(1)
    while True:
        cell = np.floor(features / resolution[group][:, None]).astype(np.int64).astype(np.uint64)
        mixed = (cell * multipliers[None, :]).sum(axis=1)
        order = np.lexsort((mixed, place))
        a, b = place[order], mixed[order]
        first = np.concatenate([[True], (a[1:] != a[:-1]) | (b[1:] != b[:-1])])
        crowded = np.bincount(group[order][first], minlength=resolution.size) > cap
        if not crowded.any():
            return order, first
        resolution[crowded] *= 2.0


def _merge(clusters: _Clusters, resolution: np.ndarray, n_x: int, n_q: int) -> _Clusters:
    """Merge clusters in the same (owner, road, task state, DFA state, grid cell of the box's
    centre); coarsen owners over CLUSTER_CAP. A merged cluster's box is the hull of its members'
    boxes widened by CORNER_MARGIN; a cluster alone in its cell keeps its box.

    (owner, x, p, q) is packed exactly into one integer, the place of `grid_merge`."""
    owner, state, alpha, lo, hi, x, p = clusters
    if owner.size == 0:
        return clusters
    n_p = int(p.max(initial=0)) + 1
    place = ((owner * n_x + x) * n_p + p) * n_q + state
    order, first = grid_merge(place, owner, 0.5 * (lo + hi), resolution, CLUSTER_CAP)
    starts = np.flatnonzero(first)
    size = np.diff(np.append(starts, order.size))
    pick = order[starts]
    merged_lo, merged_hi = lo[pick], hi[pick]
    several = size > 1
    if several.any():
        merged_lo[several] = np.maximum(
            np.minimum.reduceat(lo[order], starts, axis=0)[several] - CORNER_MARGIN, 0.0)
        merged_hi[several] = np.minimum(
            np.maximum.reduceat(hi[order], starts, axis=0)[several] + CORNER_MARGIN, 1.0)
    alpha = np.add.reduceat(alpha[order], starts, axis=0)
    return _Clusters(owner[pick], state[pick], alpha, merged_lo, merged_hi, x[pick], p[pick])
