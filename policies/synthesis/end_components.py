"""The unbounded upper bound: maximal reachability on the suffix abstraction, end components collapsed.

The abstract operator of policies/synthesis/upper_bound.py is the Bellman operator of a finite MDP:

* main states (x, q, c) for live DFA states q (accepting = target 1, rejecting = 0);
* at (x, q, c) a choice (next junction a, vertex v of the cell P_c) moves, for each symbol o of
  the next road's incident with P(o | v) > 0, with that probability to the intermediate state
  (x', q, c, o);
* at (x', q, c, o) a deterministic choice of one DFA successor q' that a label value possible on
  f_o(P_c) gives, then (x', q', next_cell(c, o)).

Its least fixed point (maximal probability of reaching acceptance) bounds the true value from above
(V* ≤ T̄ V* and the least fixed point of T̄ dominates every V with V ≤ T̄ V reached from 0). Value
iteration from 1 converges to the greatest fixed point instead, which end components that never
accept hold at 1. Following the standard construction (Haddad & Monmege; Baier et al., CAV 2017,
"interval iteration"), states that cannot reach acceptance get 0, every maximal end component of the
rest is collapsed to one state that keeps only the choices leaving it, and value iteration from 1
on the quotient converges to the least fixed point from above: every iterate is a sound bound.
The iteration from 0 runs beside it; their difference says how far the bound is from the
abstraction's own optimum. Every loop checks the deadline.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components

from trustroute.policies.logic.labelling import gamma
from trustroute.policies.synthesis.belief_cells import vertex_mask
from trustroute.policies.synthesis.rounding import MAX_OUTCOMES, model_rounding, rounded_down, rounded_up
from trustroute.policies.synthesis.upper_bound import Abstraction, can_accept
from trustroute.policies.work_clock import now as clock_now
from trustroute.policies.work_clock import spend

TARGET, ZERO = -1, -2
# units of work (policies/work_clock.py): per road of the abstraction's construction, per edges of a sweep
STATE_UNITS = 200
EDGES_PER_UNIT = 20


@dataclass(frozen=True)
class ChoiceMDP:
    """choice_state[k]: the state choice k belongs to; edges (edge_choice, edge_target, edge_prob),
    edge_target TARGET / ZERO for acceptance / rejection."""

    n_states: int
    choice_state: np.ndarray
    edge_choice: np.ndarray
    edge_target: np.ndarray
    edge_prob: np.ndarray


@dataclass(frozen=True)
class UnboundedBound:
    value: np.ndarray          # [n_x, n_q, n_cells]: sound upper bound (accepting q: 1)
    lower_value: np.ndarray    # the iteration from 0 (the abstraction's optimum from below)
    iterations: int
    gap: float                 # max over states of upper - lower iterate
    end_components: int
    complete: bool             # False when the deadline stopped the construction (value = can_accept)
    seconds: float


def abstract_mdp(abstraction: Abstraction, deadline: float) -> tuple[ChoiceMDP, int] | None:
    """The abstraction as a ChoiceMDP (None if the deadline passes); also the number of main states."""
    tables, symbols, cells = abstraction.tables, abstraction.symbols, abstraction.cells
    n_x, n_q, n_c = tables.n_x, tables.n_q, cells.n_cells
    n_main = n_x * n_q * n_c
    n_o = symbols.n_symbols
    live = ~(tables.accepting | tables.rejecting)

    def main_index(x, q, c):
        return (x * n_q + q) * n_c + c

    def inter_index(x2, q, c, o):
        return n_main + ((x2 * n_q + q) * n_c + c) * n_o + o

    def target_of(x2, q2, c2):
        return np.where(tables.accepting[q2], TARGET,
                        np.where(tables.rejecting[q2], ZERO, main_index(x2, q2, c2)))

    mask = vertex_mask(cells)                                               # [c, v]
    p_vertex = np.einsum("cvk,ok->cvo", cells.vertices, symbols.likelihood)  # P(o | v)
    choice_state, edge_choice, edge_target, edge_prob = [], [], [], []
    n_choices = 0
    live_q = np.flatnonzero(live)
    road_incident = tables.pomdp.road_incident
    for x in range(n_x):
        if clock_now() > deadline:
            return None
        spend(STATE_UNITS)
        for x2 in tables.successors[x]:
            if x2 < 0:
                continue
            outcomes = np.array(symbols.by_incident[int(road_incident[x2])], dtype=np.int64)
            # main choices (x, q, c, a, v): one per live q, cell, existing vertex
            grid_q, grid_c, grid_v = np.meshgrid(live_q, np.arange(n_c), np.arange(mask.shape[1]),
                                                 indexing="ij")
            ok = mask[grid_c, grid_v]
            qq, cc, vv = grid_q[ok], grid_c[ok], grid_v[ok]
            ids = n_choices + np.arange(qq.size)
            n_choices += qq.size
            choice_state.append(main_index(x, qq, cc))
            for o in outcomes.tolist():
                p = p_vertex[cc, vv, o]
                positive = p > 0
                edge_choice.append(ids[positive])
                edge_target.append(inter_index(x2, qq[positive], cc[positive], o))
                edge_prob.append(p[positive])
    # intermediate choices (x2, q, c, o) -> q' for every possible label value
    for x2 in range(n_x):
        if clock_now() > deadline:
            return None
        spend(STATE_UNITS)
        for o in symbols.by_incident[int(road_incident[x2])]:
            for bits in range(abstraction.possible_bits.shape[2]):
                possible_c = np.flatnonzero(abstraction.possible_bits[:, o, bits])
                if possible_c.size == 0:
                    continue
                pair_q, pair_c = np.meshgrid(live_q, possible_c, indexing="ij")
                qq, cg = pair_q.ravel(), pair_c.ravel()
                q2 = tables.next_q[qq, x2, bits]
                ids = n_choices + np.arange(qq.size)
                n_choices += qq.size
                choice_state.append(inter_index(x2, qq, cg, o))
                edge_choice.append(ids)
                edge_target.append(target_of(x2, q2, cells.next_cell[cg, o]))
                edge_prob.append(np.ones(qq.size))
    n_states = n_main + n_x * n_q * n_c * n_o
    mdp = ChoiceMDP(n_states=n_states, choice_state=np.concatenate(choice_state),
                    edge_choice=np.concatenate(edge_choice), edge_target=np.concatenate(edge_target),
                    edge_prob=np.concatenate(edge_prob))
    return mdp, n_main


def can_reach_target(mdp: ChoiceMDP) -> np.ndarray:
    """bool [n_states]: some choice sequence reaches TARGET with positive probability (a breadth-
    first search from TARGET on the reversed state graph)."""
    n = mdp.n_states
    source = mdp.choice_state[mdp.edge_choice]
    target = np.where(mdp.edge_target == TARGET, n, mdp.edge_target)
    keep = target >= 0
    reverse = csr_matrix((np.ones(int(keep.sum()), dtype=np.int8), (target[keep], source[keep])),
                         shape=(n + 1, n + 1))
    order = breadth_first_order(reverse, n, directed=True, return_predecessors=False)
    reach = np.zeros(n + 1, dtype=bool)
    reach[order] = True
    return reach[:n]


def maximal_end_components(mdp: ChoiceMDP, states: np.ndarray, deadline: float) -> np.ndarray | None:
    """int [n_states]: MEC id of each state among `states` (bool mask), -1 outside any MEC
    (None if the deadline passes)."""
    n = mdp.n_states
    choice_ok = states[mdp.choice_state].copy()
    # A choice belongs to an end component only if all its edges stay among the candidates.
    inside = (mdp.edge_target >= 0)
    inside &= np.where(inside, states[np.maximum(mdp.edge_target, 0)], False)
    bad = np.bincount(mdp.edge_choice[~inside], minlength=choice_ok.size) > 0
    choice_ok &= ~bad
    candidate = states.copy()
    while True:
        if clock_now() > deadline:
            return None
        spend(1 + mdp.edge_choice.size // EDGES_PER_UNIT)
        has_choice = np.bincount(mdp.choice_state[choice_ok], minlength=n) > 0
        candidate &= has_choice
        edge_ok = choice_ok[mdp.edge_choice] & inside
        src = mdp.choice_state[mdp.edge_choice[edge_ok]]
        dst = mdp.edge_target[edge_ok]
        keep = candidate[src] & candidate[dst]
        graph = csr_matrix((np.ones(int(keep.sum())), (src[keep], dst[keep])), shape=(n, n))
        _, component = connected_components(graph, directed=True, connection="strong")
        # drop choices with an edge leaving the source's component (or to a non-candidate)
        leaving = edge_ok & ~(candidate[mdp.choice_state[mdp.edge_choice]]
                              & np.where(mdp.edge_target >= 0, candidate[np.maximum(mdp.edge_target, 0)],
                                         False)
                              & (component[mdp.choice_state[mdp.edge_choice]]
                                 == component[np.maximum(mdp.edge_target, 0)]))
        newly_bad = (np.bincount(mdp.edge_choice[leaving], minlength=choice_ok.size) > 0) & choice_ok
        if not newly_bad.any() and (has_choice[candidate]).all():
            break
        choice_ok &= ~newly_bad
    result = np.where(candidate, component, -1)
    return result


def unbounded_bound(abstraction: Abstraction, deadline: float, tolerance: float = 1e-9,
                    max_iterations: int = 100_000) -> UnboundedBound:
    """Sound upper bound of the unbounded value on every (x, q, cell) (see the module docstring)."""
    started = time.perf_counter()
    tables, cells = abstraction.tables, abstraction.cells
    shape = (tables.n_x, tables.n_q, cells.n_cells)
    fallback = np.broadcast_to(can_accept(tables)[:, :, None], shape).astype(float)
    built = abstract_mdp(abstraction, deadline)
    if built is None:
        return UnboundedBound(fallback, np.zeros(shape), 0, 1.0, 0, False, time.perf_counter() - started)
    mdp, n_main = built
    reach = can_reach_target(mdp)
    mec = maximal_end_components(mdp, reach, deadline)
    if mec is None:
        return UnboundedBound(fallback, np.zeros(shape), 0, 1.0, 0, False, time.perf_counter() - started)
    # Quotient: every state maps to its MEC's representative (a fresh index) or to itself.
    n = mdp.n_states
    mec_ids, mec_dense = np.unique(mec[mec >= 0], return_inverse=True)
    representative = np.arange(n)
    representative[mec >= 0] = n + mec_dense
    n_quotient = n + mec_ids.size
    source = representative[mdp.choice_state]
    target = np.where(mdp.edge_target >= 0, representative[np.maximum(mdp.edge_target, 0)],
                      mdp.edge_target)
    # Drop choices all of whose edges stay in their own collapsed MEC (internal choices).
    edge_source = source[mdp.edge_choice]
    internal_edge = (target == edge_source) & (mec[mdp.choice_state[mdp.edge_choice]] >= 0)
    leaves = np.bincount(mdp.edge_choice[~internal_edge], minlength=source.size) > 0
    alive_state = np.zeros(n_quotient, dtype=bool)
    alive_state[:n] = reach
    alive_state[n:] = True
    choice_keep = leaves & alive_state[source]
    edge_keep = choice_keep[mdp.edge_choice]
    e_choice, e_target, e_prob = mdp.edge_choice[edge_keep], target[edge_keep], mdp.edge_prob[edge_keep]
    # choices renumbered densely for bincount
    kept = np.flatnonzero(choice_keep)
    dense = np.full(source.size, -1)
    dense[kept] = np.arange(kept.size)
    e_choice = dense[e_choice]
    c_state = source[kept]
    # Choices sorted by state once, so the max over a state's choices is one reduceat.
    order = np.argsort(c_state, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    e_choice = rank[e_choice]
    c_state = c_state[order]
    starts = np.flatnonzero(np.r_[True, c_state[1:] != c_state[:-1]]) if c_state.size else c_state
    owners = c_state[starts]
    upper = np.where(alive_state, 1.0, 0.0)
    lower = np.zeros(n_quotient)

    def backup(value: np.ndarray) -> np.ndarray:
        edge_value = np.where(e_target == TARGET, 1.0,
                              np.where(e_target == ZERO, 0.0, value[np.maximum(e_target, 0)]))
        choice_value = np.bincount(e_choice, weights=e_prob * edge_value, minlength=kept.size)
        out = np.zeros(n_quotient)
        if starts.size:
            out[owners] = np.maximum.reduceat(choice_value, starts)
        return np.minimum(out, 1.0)

    # Rounded up at every sweep (docs/synthesis.md, "Rounding"): a choice's value is a float sum
    # of at most MAX_OUTCOMES products with float vertex probabilities P̂(o | v), within
    # (1 ± γ_sweep) of the exact sum, so inflating it by that factor keeps every iterate at or
    # above the exact operator's image, and by induction above its least fixed point, however
    # many sweeps run. The iteration from below is deflated alike.
    sweep = gamma(tables.pomdp.n_trust + model_rounding(tables.pomdp).likelihood + MAX_OUTCOMES + 2)
    iterations = 0
    gap = 1.0
    while iterations < max_iterations and clock_now() < deadline:
        spend(1 + 2 * e_choice.size // EDGES_PER_UNIT)
        upper = np.minimum(upper, rounded_up(backup(upper), sweep))
        lower = np.maximum(lower, rounded_down(backup(lower), sweep))
        iterations += 1
        gap = float((upper - lower).max()) if upper.size else 0.0
        if gap <= tolerance:
            break
    main = np.arange(n_main)
    value = upper[representative[main]].reshape(shape)
    value_lower = lower[representative[main]].reshape(shape)
    value[:, tables.accepting, :] = 1.0
    value_lower[:, tables.accepting, :] = 1.0
    value[:, tables.rejecting, :] = 0.0
    return UnboundedBound(value=value, lower_value=value_lower, iterations=iterations, gap=gap,
                          end_components=int(mec_ids.size), complete=True,
                          seconds=time.perf_counter() - started)
