"""A policy over merged belief clusters, and its certified bounds: forward merge, backward values.

The search (search.py) keeps every belief exact, so its tree grows with the incident sequences;
on large towns with long horizons it cannot reach the decisions that matter (near the last
waypoint, where the trust threshold is read). This module solves the whole product instead, with
beliefs *enclosed* rather than exact (docs/synthesis.md, "Cluster policies"):

* Forward, level by level (t = junctions driven): a cluster is (road x, DFA state q, box [lo, hi])
  whose box-simplex B = {lo <= b <= hi, Σb = 1} encloses beliefs. From every cluster every move is
  taken; each symbol o of the next road's incident maps B into the box `box_image` returns
  (completion_value.py: the exact per-coordinate range of the filter, widened by CORNER_MARGIN);
  the DFA successors are those of every label value possible on that box (the labeller's rounding
  margin included). Children that accept are worth 1, children that reject or cannot accept within
  the junctions left (graph distance, `acceptance_distance`) 0; the rest are merged per
  (t, x, q) on a grid of side δ over a few features of the box's centre (each belief atom's value
  and the mean trust level, `merge_features`), δ doubled until the node has at most `cap` clusters.
  A merged cluster's box is the hull of its members' boxes.
* Backward: V_U(c) = max over moves of max over b in B of Σ_o P(o | b) max_{q'} V_U(child), and
  V_L(c) the same with the minimum over b and over q' (both linear in b: greedy fills,
  `linear_range`). By induction V_L(c) <= V^π(b) <= V*(b) <= V_U(c) for every b in B, where π acts
  at a belief b by the move of the cluster with the largest V_L among those at (t, x, q) whose box
  contains b (the box rows of the policy table, policies/routing/aware_table.py): b's image under
  the symbol seen lies in the child's box, so the largest V_L containing it is at least the
  child's. So the root's [V_L, V_U] brackets Pr_max, and V_L is a lower bound of π's value.

Rounding: each level's values are widened by VALUE_MARGIN (absolute), which covers the rounding of
the sums and of the greedy vertices (a few γ_{2n}) and the drift between the vehicle's float
belief and the exact posterior inside a box (both within the boxes' own CORNER_MARGIN; an argued
margin, as for the boxes themselves). Bayes rule only: the observation probabilities must be
linear in the belief.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from trustroute.policies.belief.product_mdp import ProductTables
from trustroute.policies.logic.labelling import label_margin_factor
from trustroute.policies.routing.aware_table import BoxRows
from trustroute.policies.synthesis.belief_cells import ObservationSymbols
from trustroute.policies.synthesis.budget import TimeBudget
from trustroute.policies.synthesis.completion_value import (
    CORNER_MARGIN,
    INITIAL_RESOLUTION,
    box_image,
    grid_merge,
    linear_range,
    ordered_fill,
    outcome_table,
)
from trustroute.policies.synthesis.result import ClusterAttempt, ClusterRun, SynthesisResult, SynthesisStats
from trustroute.policies.synthesis.upper_bound import acceptance_distance
from trustroute.policies.work_clock import CAPS, spend
from trustroute.policies.work_clock import now as clock_now

VALUE_MARGIN = 1e-12              # every level's lower values are lowered, upper raised, by this
CLUSTER_CAPS = (16, 64, 256, 512)  # clusters per (t, x, q), tried in turn while the gap exceeds tau
# Peak memory per cluster held (boxes, edges, values): 550-570 bytes measured on the 200-junction
# grid at H = 40 (caps 256 and 512); a cap whose predicted clusters would exceed MEMORY_BUDGET is
# not tried. Time and clusters grow at most in proportion to the cap (measured: 3x and 3.4x from
# 64 to 256, 2.1x and 2x from 256 to 512), so that is the prediction.
BYTES_PER_CLUSTER = 700
MEMORY_BUDGET = 600e6
EDGE_UNITS = 28                   # units of work (policies/work_clock.py) per edge and outcome of a level
BACKWARD_SHARE = 0.25             # the forward pass stops where what follows would pass the deadline


@dataclass(frozen=True, eq=False)
class ClusterSolution:
    """lower <= Pr_max <= upper from the root beliefs; lower <= the value of the policy `rows`
    (with the free completion where no box holds the belief). cap: clusters per (t, x, q)."""

    lower: float
    upper: float
    rows: BoxRows
    cap: int
    clusters: int
    seconds: float


@dataclass(frozen=True, eq=False)
class _Level:
    """One level's clusters and their moves: edges (cluster r, slot a) with a symbol per outcome
    column, and candidates (edge, outcome, DFA successor) with a child cluster or a terminal value."""

    x: np.ndarray
    q: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    edge_cluster: np.ndarray
    edge_slot: np.ndarray
    edge_symbols: np.ndarray       # [E, width], -1 where the incident has fewer outcomes
    candidate_edge: np.ndarray
    candidate_outcome: np.ndarray
    candidate_child: np.ndarray    # cluster of the next level, or -1: terminal
    candidate_terminal: np.ndarray  # 1.0 accepting, 0.0 otherwise (used where child < 0)


def merge_features(centre: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
    """[r, m + 1]: what the merge grid is laid over: each belief atom's affine part c·b and the mean
    trust level scaled to [0, 1]. Beliefs that agree on these read the same labels and (trust moving
    by one level at a time) nearly the same futures; a grid over all n coordinates spends the cap on
    differences that do not matter (measured: the same cap gives a gap 3x larger)."""
    n = centre.shape[1]
    mean = centre @ (np.arange(n) / max(n - 1, 1))
    return np.column_stack([centre @ coeffs.T, mean]) if coeffs.size else mean[:, None]


def _merge(node: np.ndarray, features: np.ndarray, cap: int) -> np.ndarray:
    """The cluster index of each candidate: candidates of one node merge on the finest grid
    (δ = INITIAL_RESOLUTION doubled per node) with at most `cap` cells (`grid_merge`)."""
    if node.size == 0:
        return np.zeros(0, dtype=np.int64)
    nodes, node_of = np.unique(node, return_inverse=True)
    order, first = grid_merge(node, node_of, features, np.full(nodes.size, INITIAL_RESOLUTION), cap)
    cluster = np.empty(node.size, dtype=np.int64)
    cluster[order] = np.cumsum(first) - 1
    return cluster


def _label_options(tables: ProductTables, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """bool [r, 2**m]: the belief-label valuations possible on each box (the labeller's rounding
    margin included); bit j of a valuation is belief atom j (ProductTables.next_q's last axis)."""
    coeffs, offsets = tables.belief_coeffs, tables.belief_offsets
    m = offsets.size
    if m == 0:
        return np.ones((lo.shape[0], 1), dtype=bool)
    n = lo.shape[1]
    margin = label_margin_factor(n) * np.abs(coeffs).sum(axis=1) + CORNER_MARGIN
    ranges = [linear_range(lo, hi, coeffs[k]) for k in range(m)]
    can_true = np.stack([r[1] for r in ranges], axis=1) > offsets - margin
    can_false = np.stack([r[0] for r in ranges], axis=1) <= offsets + margin
    bits = (np.arange(2 ** m)[:, None] >> np.arange(m)[None, :]) & 1
    return np.where(bits[None] == 1, can_true[:, None, :], can_false[:, None, :]).all(axis=2)


def _images(lo: np.ndarray, hi: np.ndarray, cluster: np.ndarray, symbol: np.ndarray,
            symbols: ObservationSymbols) -> tuple[np.ndarray, np.ndarray]:
    """The image box of cluster[i]'s box under symbol[i], each (cluster, symbol) pair computed once;
    belief-preserving symbols map a box to itself (the filter returns such beliefs bit for bit).
    Images of points are widened by CORNER_MARGIN too (`box_image` leaves them exact): the acting
    rule needs the box to hold the vehicle's float belief, whose rounding may differ from this
    computation's by an ulp."""
    key = cluster * symbols.n_symbols + symbol
    unique, inverse = np.unique(key, return_inverse=True)
    which, sym = unique // symbols.n_symbols, unique % symbols.n_symbols
    out_lo, out_hi = lo[which].copy(), hi[which].copy()
    for o in np.unique(sym).tolist():
        if symbols.identity[o]:
            continue
        here = np.flatnonzero(sym == o)
        image_lo, image_hi = box_image(lo[which[here]], hi[which[here]], symbols, o)
        point = image_lo == image_hi
        out_lo[here] = np.where(point, np.maximum(image_lo - CORNER_MARGIN, 0.0), image_lo)
        out_hi[here] = np.where(point, np.minimum(image_hi + CORNER_MARGIN, 1.0), image_hi)
    return out_lo[inverse], out_hi[inverse]


def _forward(tables: ProductTables, symbols: ObservationSymbols, roots_q: list[int], belief: np.ndarray,
             horizon: int, cap: int, deadline: float) -> list[_Level] | None:
    """The levels 0..horizon-1 (None: stopped by the deadline)."""
    distance = acceptance_distance(tables)
    outcomes = outcome_table(symbols)
    width = outcomes.shape[1]
    incident_of = tables.pomdp.road_incident
    n = belief.size
    live = [q for q in roots_q if not tables.accepting[q] and not tables.rejecting[q]
            and distance[tables.start, q] <= horizon]
    x = np.full(len(live), tables.start, dtype=np.int64)
    q = np.array(live, dtype=np.int64)
    lo = np.broadcast_to(belief, (len(live), n)).copy()
    hi = lo.copy()
    levels: list[_Level] = []
    budget = TimeBudget.until(deadline)
    for t in range(horizon):
        if x.size == 0:
            break
        # the backward pass and the rows take about 15 % of the forward pass's time (measured;
        # BACKWARD_SHARE leaves room for a slower machine)
        if not budget.fits(BACKWARD_SHARE * budget.used()):
            return None
        slots = tables.successors[x]
        edge_cluster, edge_slot = np.nonzero(slots >= 0)
        spend(EDGE_UNITS * edge_cluster.size * width)
        next_road = slots[edge_cluster, edge_slot]
        edge_symbols = outcomes[incident_of[next_road]]
        parts = []
        for j in range(width):
            edges = np.flatnonzero(edge_symbols[:, j] >= 0)
            if edges.size == 0:
                continue
            lo2, hi2 = _images(lo, hi, edge_cluster[edges], edge_symbols[edges, j], symbols)
            fits = _label_options(tables, lo2, hi2)
            for bits in range(fits.shape[1]):
                pick = np.flatnonzero(fits[:, bits])
                q2 = tables.next_q[q[edge_cluster[edges[pick]]], next_road[edges[pick]], bits]
                parts.append((edges[pick], np.full(pick.size, j), q2, lo2[pick], hi2[pick]))
        c_edge, c_outcome, c_q, c_lo, c_hi = (np.concatenate([p[k] for p in parts]) for k in range(5))
        # one candidate per (edge, outcome, successor), whichever label values lead there
        _, first = np.unique((c_edge * width + c_outcome) * tables.n_q + c_q, return_index=True)
        c_edge, c_outcome, c_q, c_lo, c_hi = (a[first] for a in (c_edge, c_outcome, c_q, c_lo, c_hi))
        c_x = next_road[c_edge]
        accepting = tables.accepting[c_q]
        going = (~accepting & ~tables.rejecting[c_q]
                 & (distance[c_x, c_q] <= horizon - (t + 1))).nonzero()[0]
        node = c_x[going] * tables.n_q + c_q[going]
        centre = 0.5 * (c_lo[going] + c_hi[going])
        cluster = _merge(node, merge_features(centre, tables.belief_coeffs), cap)
        child = np.full(c_edge.size, -1, dtype=np.int64)
        child[going] = cluster
        levels.append(_Level(x=x, q=q, lo=lo, hi=hi, edge_cluster=edge_cluster, edge_slot=edge_slot,
                             edge_symbols=edge_symbols, candidate_edge=c_edge, candidate_outcome=c_outcome,
                             candidate_child=child, candidate_terminal=accepting.astype(float)))
        count = int(cluster.max()) + 1 if cluster.size else 0
        x = np.zeros(count, dtype=np.int64)
        q = np.zeros(count, dtype=np.int64)
        x[cluster], q[cluster] = c_x[going], c_q[going]
        lo = np.full((count, n), np.inf)
        hi = np.full((count, n), -np.inf)
        np.minimum.at(lo, cluster, c_lo[going])
        np.maximum.at(hi, cluster, c_hi[going])
        several = np.bincount(cluster, minlength=count) > 1
        lo[several] = np.maximum(lo[several] - CORNER_MARGIN, 0.0)
        hi[several] = np.minimum(hi[several] + CORNER_MARGIN, 1.0)
    return levels


def _backward(levels: list[_Level], symbols: ObservationSymbols
              ) -> tuple[list[tuple[np.ndarray, np.ndarray, np.ndarray]], np.ndarray, np.ndarray]:
    """Per level (V_L, V_U, the move of V_L per cluster); and the root level's V_L, V_U."""
    below_lower = below_upper = np.zeros(0)
    out = []
    likelihood = symbols.likelihood
    for level in reversed(levels):
        child = level.candidate_child
        has_child = child >= 0
        index = np.where(has_child, child, 0)
        low = np.where(has_child, below_lower[index] if below_lower.size else 0.0, level.candidate_terminal)
        high = np.where(has_child, below_upper[index] if below_upper.size else 0.0, level.candidate_terminal)
        n_edges, width = level.edge_symbols.shape
        outcome_low = np.full((n_edges, width), np.inf)
        outcome_high = np.full((n_edges, width), -np.inf)
        np.minimum.at(outcome_low, (level.candidate_edge, level.candidate_outcome), low)
        np.maximum.at(outcome_high, (level.candidate_edge, level.candidate_outcome), high)
        present = level.edge_symbols >= 0
        outcome_low = np.where(present, outcome_low, 0.0)
        outcome_high = np.where(present, outcome_high, 0.0)
        weights = likelihood[np.maximum(level.edge_symbols, 0)] * present[:, :, None]   # [E, w, n]
        lo, hi = level.lo[level.edge_cluster], level.hi[level.edge_cluster]
        move_low = _extreme(lo, hi, (weights * outcome_low[:, :, None]).sum(axis=1), minimum=True)
        move_high = _extreme(lo, hi, (weights * outcome_high[:, :, None]).sum(axis=1), minimum=False)
        count = level.x.size
        lower = np.full(count, -np.inf)
        upper = np.full(count, -np.inf)
        np.maximum.at(lower, level.edge_cluster, move_low)
        np.maximum.at(upper, level.edge_cluster, move_high)
        # the move of V_L: the first slot attaining it
        best = move_low >= lower[level.edge_cluster]
        action = np.full(count, -1, dtype=np.int64)
        chosen = np.flatnonzero(best)[::-1]
        action[level.edge_cluster[chosen]] = level.edge_slot[chosen]
        lower = np.maximum(lower - VALUE_MARGIN, 0.0)
        upper = np.minimum(upper + VALUE_MARGIN, 1.0)
        out.append((lower, upper, action))
        below_lower, below_upper = lower, upper
    out.reverse()
    return out, below_lower, below_upper


def _extreme(lo: np.ndarray, hi: np.ndarray, coeffs: np.ndarray, minimum: bool) -> np.ndarray:
    """min (or max) of coeffs[i]·b over box-simplex i, a greedy fill in coefficient order."""
    order = np.argsort(coeffs if minimum else -coeffs, axis=1, kind="stable")
    vertex = ordered_fill(lo, hi, order[:, None, :])[:, 0, :]
    return (vertex * coeffs).sum(axis=1)


def solve_clusters(tables: ProductTables, symbols: ObservationSymbols, roots_q: list[int],
                   horizon: int, cap: int, deadline: float) -> ClusterSolution | None:
    """The cluster policy with at most `cap` clusters per (t, x, q) and its root bounds (minimum of
    V_L and maximum of V_U over the root DFA states `roots_q`, which differ only where the prior
    sits on a threshold). None when the deadline stops the forward pass."""
    if symbols.rule != "bayes":
        raise ValueError("cluster policies need the Bayes rule (observation mass linear in the belief)")
    started = time.perf_counter()
    belief = np.asarray(tables.pomdp.initial_belief, dtype=float)
    levels = _forward(tables, symbols, roots_q, belief, horizon, cap, deadline)
    if levels is None:
        return None
    values, root_lower, root_upper = _backward(levels, symbols)
    live = {q: i for i, q in enumerate(levels[0].q.tolist())} if levels else {}
    lower, upper = [], []
    for q in roots_q:
        if tables.accepting[q]:
            lower.append(1.0)
            upper.append(1.0)
        elif q in live:
            lower.append(float(root_lower[live[q]]))
            upper.append(float(root_upper[live[q]]))
        else:
            lower.append(0.0)
            upper.append(0.0)
    # rows worth 0 are left out: where no box holds a belief the free completion (worth >= 0) acts
    keep = [np.flatnonzero(value[0] > 0) for value in values]
    pairs = list(zip(levels, values, keep, strict=True))
    rows = BoxRows.empty(belief.size) if not pairs else BoxRows(
        t=np.concatenate([np.full(k.size, t) for t, k in enumerate(keep)]),
        x=np.concatenate([lv.x[k] for lv, _, k in pairs]),
        q=np.concatenate([lv.q[k] for lv, _, k in pairs]),
        lo=np.concatenate([lv.lo[k] for lv, _, k in pairs]),
        hi=np.concatenate([lv.hi[k] for lv, _, k in pairs]),
        value=np.concatenate([v[0][k] for _, v, k in pairs]),
        action=np.concatenate([v[2][k] for _, v, k in pairs]))
    clusters = sum(lv.x.size for lv in levels)
    return ClusterSolution(lower=min(lower), upper=max(upper), rows=rows, cap=cap, clusters=clusters,
                           seconds=time.perf_counter() - started)


def best_cluster_solution(tables: ProductTables, symbols: ObservationSymbols, roots_q: list[int],
                          horizon: int, tau: float, deadline: float,
                          caps: tuple[int, ...] = CLUSTER_CAPS, enough: float | None = None
                          ) -> tuple[ClusterSolution | None, float, list[ClusterAttempt]]:
    """Cluster policies with growing caps while the gap exceeds tau (and L is below `enough`, when
    given: an unbounded problem's U - tau) and the next one is predicted (the last's time and
    clusters times the ratio of the caps) to end before the deadline within MEMORY_BUDGET.
    Returns (the solution of the largest L, the smallest U of all, a record per cap tried)."""
    best: ClusterSolution | None = None
    previous: ClusterSolution | None = None       # the last cap's solution
    previous_used = 0.0                           # its seconds on the clock
    upper = 1.0
    tried: list[ClusterAttempt] = []
    budget = TimeBudget.until(deadline)
    for cap in caps:
        if best is not None and (upper - best.lower <= tau or (enough is not None and best.lower >= enough)):
            break
        if previous is not None:
            growth = cap / previous.cap
            if (not budget.fits(growth * previous_used)
                    or growth * previous.clusters * BYTES_PER_CLUSTER > MEMORY_BUDGET):
                break
        began = clock_now()
        solution = solve_clusters(tables, symbols, roots_q, horizon, cap, deadline)
        previous_used = clock_now() - began
        if solution is None:
            tried.append(ClusterAttempt(cap=cap))
            break
        tried.append(ClusterAttempt(cap=cap, lower=solution.lower, upper=solution.upper,
                                    clusters=solution.clusters, rows=solution.rows.rows,
                                    seconds=solution.seconds))
        upper = min(upper, solution.upper)
        if best is None or solution.lower > best.lower:
            best = solution
        previous = solution
    return best, upper, tried


def reached_cluster_cap(stats: object, lower: float, upper: float) -> bool:
    """Whether a synthesis' bounds (`lower`, `upper`) are those of its cluster policies at their
    largest cap (CLUSTER_CAPS): the search before them had looser bounds, so a longer time limit,
    which only lengthens that search, need not move them."""
    if not isinstance(stats, SynthesisStats) or not stats.runs:
        return False
    last = stats.runs[-1]
    return (isinstance(last, ClusterRun) and last.cluster_cap == CLUSTER_CAPS[-1]
            and (last.lower, last.upper) == (lower, upper))


def own_cap(run: SynthesisResult) -> str | None:
    """The cap of a synthesis' own (work_clock.CAPS) whose bounds it returned, if any, for a run of
    either kind: a belief-MDP synthesis' cluster policies' largest (`reached_cluster_cap`), else
    the cap its statistics name (`stopped`: the end of a belief-MDP synthesis' unbounded schedule
    run whole, belief_synthesis.py, or a trust-state synthesis' own, JOINT_STOPS)."""
    if reached_cluster_cap(run.stats, run.lower, run.upper):
        return "cluster cap"
    return run.stats.stopped if run.stats.stopped in CAPS else None
