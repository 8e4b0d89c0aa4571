"""Policy synthesis with certified bounds: lower <= Pr_max(spec) <= upper (docs/model.md, "What L and U
mean").

Method (bounded heuristic search over the product belief MDP, with a sound abstraction at the frontier):

* The exact product belief MDP is unfolded from (start, initial belief, q_0) as an AND-OR graph:
  one node per distinct (junctions t, road x, DFA state q, belief bytes) — identical beliefs at the
  same depth are merged, never approximated. A node's children are, per next junction, the
  observation symbols with their exact probabilities and exact Bayes (or "paper") posteriors.
* Every node carries [L, U]. Unexpanded nodes: L = 0, U = the suffix abstraction's bound at the
  node's cell (policies/synthesis/upper_bound.py; the cell is the node's last k belief-changing symbols,
  which it knows exactly). Terminal nodes are exact: accepted 1, rejected 0, horizon reached 0.
  Expanded nodes: U = min(U, max_a Σ_o p U_child) and L = max_a Σ_o p L_child.
* Refinement (AO*/HSVI style): expand, in batches, the frontier nodes carrying the most of the root's
  gap — reach probability under the upper-greedy policy times (U - L) — until U - L <= tau at the
  root, the frontier is exhausted, or the time limit.
* The returned policy takes at every expanded node the action maximising L (ties: U); lower is the
  value of exactly that policy with every unexpanded node counted as failure, so the policy's true
  value is at least `lower`. It is a policies.routing.aware_table.BeliefTablePolicy (acts on any belief).

Horizon H: at most H junctions (the study measures "policy, then fallback after 20", so H = 20 is
the natural companion). Unbounded (horizon=None): upper is the abstraction's least fixed point with
end components collapsed (policies/synthesis/end_components.py), tightened by a search of the
unbounded problem itself (open nodes, including those deeper than UNBOUNDED_DEPTH, valued by that
bound); lower is the best of that search and bounded searches with growing H (their policies are
policies for the unbounded problem too, worth at least their bounded value).

Labels at thresholds: a belief within the rounding margin of a belief atom's hyperplane
(labelling.Labeller.belief_margins) gives one child per DFA state it could lead to; L takes the
minimum over them and U the maximum (docs/synthesis.md, "Labels at thresholds"). Horizons shorter
than the road x DFA graph distance to acceptance are answered without search (L = U = 0).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.product_mdp import ProductTables, build_product
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.routing.aware_table import BeliefTablePolicy, PolicyTable
from trustroute.policies.synthesis.belief_cells import apply_symbol, observation_symbols, suffix_cells
from trustroute.policies.synthesis.end_components import unbounded_bound
from trustroute.policies.synthesis.upper_bound import (
    Abstraction,
    acceptance_distance,
    bounded_upper,
    build_abstraction,
)

CELL_BUDGET = 5000          # automatic suffix length: the longest k with n_symbols**k <= this
DEFAULT_BATCH = 4096
UNBOUNDED_HORIZONS = (20, 30, 40, 60, 80, 120, 160)
UNBOUNDED_DEPTH = 60        # the unbounded search leaves nodes this deep open (<= evaluate's cap)
UNBOUNDED_STATE_BUDGET = 20_000
UNBOUNDED_BOUND_SHARE = 0.3  # share of the time limit the end-component bound may take
BOUNDED_ENTRY_BUDGET = 20_000_000   # floats of the bounded abstraction (160 MB)
FINISH_SHARE = 0.04          # share of the time limit kept for finishing after the last check

FRONTIER, EXPANDED, ACCEPTED, ZERO = 0, 1, 2, 3


@dataclass(frozen=True, eq=False)
class SynthesisResult:
    """lower <= Pr_max <= upper; lower is the value of `policy` (a certified lower bound of it).

    horizon: the junction horizon solved for (None: unbounded); stats: how the bounds were obtained
    (per bounded run: nodes, expanded nodes, open frontier, the abstraction's root bound).
    """

    policy: BeliefTablePolicy
    lower: float
    upper: float
    seconds: float
    stats: dict = field(default_factory=dict)
    horizon: int | None = None
    belief_rule: str = "bayes"

    @property
    def gap(self) -> float:
        return self.upper - self.lower


class _Graph:
    """Growable node arrays of the unfolded product belief MDP."""

    def __init__(self, n_trust: int, n_actions: int, n_outcomes: int) -> None:
        self.n = 0
        self.n_actions, self.n_outcomes = n_actions, n_outcomes
        capacity = 1024
        self.level = np.zeros(capacity, dtype=np.int64)
        self.x = np.zeros(capacity, dtype=np.int64)
        self.q = np.zeros(capacity, dtype=np.int64)
        self.cell = np.zeros(capacity, dtype=np.int64)
        self.belief = np.zeros((capacity, n_trust))
        self.upper = np.zeros(capacity)
        self.lower = np.zeros(capacity)
        # value of the L-greedy choice with every label read strictly, as this machine's labeller
        # does (no alternates): the tie-breaker among actions of equal L, and a reported figure.
        self.strict = np.zeros(capacity)
        self.kind = np.zeros(capacity, dtype=np.int8)
        self.child = np.full((capacity, n_actions, n_outcomes), -1, dtype=np.int64)
        self.prob = np.zeros((capacity, n_actions, n_outcomes))
        self.memo: list[dict[tuple[int, int, bytes], int]] = []
        self.expanded_by_level: list[list[int]] = []
        # Labels at thresholds: an outcome whose belief is within the rounding margin of a belief
        # atom's hyperplane has one child per DFA state it could lead to. child/prob hold the one
        # the strict label reads; the others are "alternates" (parent, slot, outcome, child),
        # grouped by the parent's level. L takes the minimum over them, U the maximum.
        self.alternates: dict[int, list[np.ndarray]] = {}
        self._alternates_joined: dict[int, tuple[np.ndarray, ...]] = {}

    def add_alternates(self, level: int, parent: np.ndarray, slot: np.ndarray, outcome: np.ndarray,
                       child: np.ndarray) -> None:
        if parent.size == 0:
            return
        self.alternates.setdefault(level, []).append(np.stack([parent, slot, outcome, child]))
        self._alternates_joined.pop(level, None)

    def alternates_of(self, level: int | None) -> tuple[np.ndarray, ...]:
        """(parent, slot, outcome, child) of the alternates of parents at `level` (None: all)."""
        if level is None:
            parts = [self.alternates_of(lv) for lv in sorted(self.alternates)]
            if not parts:
                return tuple(np.zeros(0, dtype=np.int64) for _ in range(4))
            return tuple(np.concatenate([p[j] for p in parts]) for j in range(4))
        joined = self._alternates_joined.get(level)
        if joined is None:
            chunks = self.alternates.get(level)
            if not chunks:
                return tuple(np.zeros(0, dtype=np.int64) for _ in range(4))
            stacked = np.concatenate(chunks, axis=1)
            joined = tuple(stacked[j] for j in range(4))
            self._alternates_joined[level] = joined
        return joined

    def _grow(self, needed: int) -> None:
        capacity = self.level.shape[0]
        if needed <= capacity:
            return
        new = max(needed, 2 * capacity)
        for name in ("level", "x", "q", "cell", "upper", "lower", "strict", "kind"):
            old = getattr(self, name)
            grown = np.zeros(new, dtype=old.dtype)
            grown[:capacity] = old
            setattr(self, name, grown)
        belief = np.zeros((new, self.belief.shape[1]))
        belief[:capacity] = self.belief
        self.belief = belief
        child = np.full((new, self.n_actions, self.n_outcomes), -1, dtype=np.int64)
        child[:capacity] = self.child
        self.child = child
        prob = np.zeros((new, self.n_actions, self.n_outcomes))
        prob[:capacity] = self.prob
        self.prob = prob

    def add(self, level: int, x: np.ndarray, q: np.ndarray, cell: np.ndarray, belief: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
        """Ids of the nodes (level, x, q, belief), creating missing ones; and a mask of new ones."""
        while len(self.memo) <= level:
            self.memo.append({})
            self.expanded_by_level.append([])
        memo = self.memo[level]
        ids = np.empty(x.size, dtype=np.int64)
        new = np.zeros(x.size, dtype=bool)
        start = self.n
        self._grow(self.n + x.size)
        for i, key in enumerate(zip(x.tolist(), q.tolist(), (row.tobytes() for row in belief),
                                    strict=True)):
            node = memo.get(key)
            if node is None:
                node = self.n
                memo[key] = node
                self.n += 1
                new[i] = True
            ids[i] = node
        created = ids[new]
        self.level[created] = level
        self.x[created] = x[new]
        self.q[created] = q[new]
        self.cell[created] = cell[new]
        self.belief[created] = belief[new]
        self.kind[created] = FRONTIER
        assert self.n == start + created.size
        return ids, new


class _Search:
    def __init__(self, tables: ProductTables, rule: BeliefRule, horizon: int | None, suffix_length: int,
                 started: float, deadline: float, unbounded_value: np.ndarray | None = None,
                 abstraction: Abstraction | None = None) -> None:
        self.tables, self.rule, self.horizon = tables, rule, horizon
        self.started = started
        pomdp = tables.pomdp
        if abstraction is not None:        # built once per synthesize call and shared by its runs
            self.symbols, self.cells = abstraction.symbols, abstraction.cells
        else:
            self.symbols = observation_symbols(pomdp, rule)
            self.cells = suffix_cells(self.symbols, suffix_length)
        self.distance = acceptance_distance(tables)
        if horizon is not None:
            if abstraction is None:
                abstraction = build_abstraction(tables, self.symbols, self.cells)
            self.bound = bounded_upper(abstraction, horizon, deadline, unbounded_value)
            self.bound_note = "exact backward induction on the abstraction"
        else:
            self.bound = [unbounded_value]
            self.bound_note = ("the unbounded abstraction's least fixed point from above, end "
                               "components collapsed (policies/synthesis/end_components.py)")
        self.abstraction_seconds = time.perf_counter() - started
        n_outcomes = max(len(s) for s in self.symbols.by_incident)
        self.slot_of_symbol = np.zeros(self.symbols.n_symbols, dtype=np.int64)
        for members in self.symbols.by_incident:
            for j, o in enumerate(members):
                self.slot_of_symbol[o] = j
        self.graph = _Graph(pomdp.n_trust, tables.successors.shape[1], n_outcomes)

    def frontier_upper(self, level: int, x: np.ndarray, q: np.ndarray, cell: np.ndarray) -> np.ndarray:
        return self.bound[min(level, len(self.bound) - 1)][x, q, cell]

    def classify(self, ids: np.ndarray, level: int) -> None:
        """Initialise new nodes: terminal values, or the frontier's abstract bound."""
        g, tables = self.graph, self.tables
        q = g.q[ids]
        accepted = tables.accepting[q]
        g.kind[ids[accepted]] = ACCEPTED
        g.upper[ids[accepted]] = g.lower[ids[accepted]] = g.strict[ids[accepted]] = 1.0
        rest = ids[~accepted]
        if rest.size == 0:
            return
        upper = np.minimum(1.0, self.frontier_upper(level, g.x[rest], g.q[rest], g.cell[rest]))
        dead = tables.rejecting[g.q[rest]] | (upper <= 0.0)
        if self.horizon is not None:
            # graph distance: acceptance needs more junctions than are left -> exactly 0
            dead |= self.distance[g.x[rest], g.q[rest]] > self.horizon - level
        g.kind[rest[dead]] = ZERO
        g.upper[rest[dead]] = 0.0
        g.lower[rest[dead]] = 0.0
        g.strict[rest[dead]] = 0.0
        live = rest[~dead]
        g.upper[live] = upper[~dead]
        g.lower[live] = 0.0
        g.strict[live] = 0.0

    def possible_q(self, q: np.ndarray, x2: np.ndarray, belief: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """DFA states after reading (x2, belief) from q: (strict, rows, other).

        strict[i]: the state the labeller reads (what the vehicle and `evaluate` do); (rows, other):
        for row rows[j] the further state other[j] that a label within the rounding margin of its
        threshold could give (labelling.Labeller.belief_margins).
        """
        tables = self.tables
        strict = tables.step(q, x2, belief)
        empty = np.zeros(0, dtype=np.int64)
        if not tables.belief_atom_names or q.size == 0:
            return strict, empty, empty
        truth, either = tables.labeller.belief_margins(belief)
        ambiguous = np.flatnonzero(either.any(axis=1))
        if ambiguous.size == 0:
            return strict, empty, empty
        m = truth.shape[1]
        rows, other = [], []
        for bits in range(2 ** m):
            value = ((bits >> np.arange(m)) & 1).astype(bool)
            fits = ((value[None, :] == truth[ambiguous]) | either[ambiguous]).all(axis=1)
            members = ambiguous[fits]
            q_bits = tables.next_q[q[members], x2[members], bits]
            differs = q_bits != strict[members]
            rows.append(members[differs])
            other.append(q_bits[differs])
        rows_all, other_all = np.concatenate(rows), np.concatenate(other)
        if rows_all.size:
            pair = np.unique(np.stack([rows_all, other_all], axis=1), axis=0)
            rows_all, other_all = pair[:, 0], pair[:, 1]
        return strict, rows_all, other_all

    def roots(self) -> np.ndarray:
        """Root nodes: one per DFA state position 0 can be read as (one unless the prior sits on a
        threshold); the root value is the minimum of their L and the maximum of their U."""
        tables = self.tables
        b0 = np.asarray(tables.pomdp.initial_belief, dtype=float)[None, :]
        x0 = np.array([tables.start])
        strict, _, other = self.possible_q(np.array([tables.dfa.initial]), x0, b0)
        qs = np.concatenate([strict, other])
        ids, _ = self.graph.add(0, np.repeat(x0, qs.size), qs, np.zeros(qs.size, dtype=np.int64),
                                np.repeat(b0, qs.size, axis=0))
        self.classify(ids, 0)
        return ids

    def expand(self, nodes: np.ndarray) -> None:
        g, tables, symbols = self.graph, self.tables, self.symbols
        by_level: dict[int, list[int]] = {}
        for node, level in zip(nodes.tolist(), g.level[nodes].tolist(), strict=True):
            by_level.setdefault(level, []).append(node)
        for level, members in sorted(by_level.items()):
            parents = np.array(members, dtype=np.int64)
            rows_parent, rows_slot, rows_symbol, rows_x2 = [], [], [], []
            for a in range(tables.successors.shape[1]):
                x2 = tables.successors[g.x[parents], a]
                valid = x2 >= 0
                incident = tables.pomdp.road_incident[np.where(valid, x2, 0)]
                for o in range(symbols.n_symbols):
                    hit = valid & (incident == symbols.incident[o])
                    if hit.any():
                        rows_parent.append(parents[hit])
                        rows_slot.append(np.full(int(hit.sum()), a))
                        rows_symbol.append(np.full(int(hit.sum()), o))
                        rows_x2.append(x2[hit])
            parent = np.concatenate(rows_parent)
            slot = np.concatenate(rows_slot)
            symbol = np.concatenate(rows_symbol)
            x2 = np.concatenate(rows_x2)
            belief, probability = apply_symbol(g.belief[parent], symbols, symbol)
            keep = probability > 0
            parent, slot, symbol, x2, belief, probability = (
                a[keep] for a in (parent, slot, symbol, x2, belief, probability))
            q2, alt_rows, alt_q = self.possible_q(g.q[parent], x2, belief)
            cell2 = self.cells.next_cell[g.cell[parent], symbol]
            ids, new = g.add(level + 1, x2, q2, cell2, belief)
            outcome = self.slot_of_symbol[symbol]
            g.child[parent, slot, outcome] = ids
            g.prob[parent, slot, outcome] = probability
            self.classify(ids[new], level + 1)
            if alt_rows.size:
                alt_ids, alt_new = g.add(level + 1, x2[alt_rows], alt_q, cell2[alt_rows],
                                         belief[alt_rows])
                self.classify(alt_ids[alt_new], level + 1)
                g.add_alternates(level, parent[alt_rows], slot[alt_rows], outcome[alt_rows], alt_ids)
            g.kind[parents] = EXPANDED
            g.expanded_by_level[level].extend(members)

    def action_values(self, nodes: np.ndarray, values: np.ndarray, pessimistic: bool | None,
                      level: int | None = None) -> np.ndarray:
        """Σ_o p(o) value(child) per legal action (-1 for illegal slots), for expanded `nodes`.

        An outcome with alternates (a label within the rounding margin) takes the minimum of its
        children's values when `pessimistic` (L), the maximum otherwise (U). `level`: all nodes
        are at this level (only that level's alternates are looked at). pessimistic None: the
        strict children only (alternates ignored)."""
        g = self.graph
        child = g.child[nodes]
        child_value = np.where(child >= 0, values[np.maximum(child, 0)], 0.0)
        parent, slot, outcome, alt_child = g.alternates_of(level if pessimistic is not None else -1)
        if parent.size:
            order = np.argsort(nodes, kind="stable")
            sorted_nodes = nodes[order]
            where = np.searchsorted(sorted_nodes, parent)
            where = np.minimum(where, sorted_nodes.size - 1)
            hit = sorted_nodes[where] == parent
            if hit.any():
                index = (order[where[hit]], slot[hit], outcome[hit])
                combine = np.minimum.at if pessimistic else np.maximum.at
                combine(child_value, index, values[alt_child[hit]])
        q = (g.prob[nodes] * child_value).sum(axis=2)
        legal = self.tables.successors[g.x[nodes]] >= 0
        return np.where(legal, q, -1.0)

    def backup(self) -> None:
        g = self.graph
        for level in range(len(g.expanded_by_level) - 1, -1, -1):
            members = g.expanded_by_level[level]
            if not members:
                continue
            nodes = np.array(members, dtype=np.int64)
            g.upper[nodes] = np.minimum(
                g.upper[nodes], self.action_values(nodes, g.upper, False, level).max(axis=1))
            lower_q = self.action_values(nodes, g.lower, True, level)
            g.lower[nodes] = np.maximum(g.lower[nodes], lower_q.max(axis=1))
            # strict value of the policy's own choice (best L, ties by strict value)
            strict_q = self.action_values(nodes, g.strict, None, level)
            tied = lower_q >= lower_q.max(axis=1, keepdims=True)
            g.strict[nodes] = np.where(tied, strict_q, -1.0).max(axis=1)

    def reach(self, roots: np.ndarray, every_action: bool = False) -> np.ndarray:
        """Probability of reaching each node under the upper-greedy policy (alternates of an
        outcome each get its full probability: either may be the one that happens). every_action:
        every action carries the node's full mass instead (used once the upper-greedy frontier is
        closed while the gap is not, as at thresholds where L takes the worse alternate)."""
        g = self.graph
        reach = np.zeros(g.n)
        reach[roots] = 1.0
        for level, members in enumerate(g.expanded_by_level):
            if not members:
                continue
            nodes = np.array(members, dtype=np.int64)
            nodes = nodes[reach[nodes] > 0]
            if nodes.size == 0:
                continue
            values = self.action_values(nodes, g.upper, False, level)
            if every_action:
                chosen = values >= 0                                   # [nodes, actions]
            else:
                chosen = np.zeros(values.shape, dtype=bool)
                chosen[np.arange(nodes.size), values.argmax(axis=1)] = True
            mass = reach[nodes, None, None] * g.prob[nodes] * chosen[:, :, None]
            child = g.child[nodes]
            ok = child >= 0
            np.add.at(reach, child[ok], mass[ok])
            parent, slot, outcome, alt_child = g.alternates_of(level)
            if parent.size:
                position = dict(zip(nodes.tolist(), range(nodes.size), strict=True))
                for p, a, o, c in zip(parent.tolist(), slot.tolist(), outcome.tolist(),
                                      alt_child.tolist(), strict=True):
                    i = position.get(p)
                    if i is not None:
                        reach[c] += mass[i, a, o]
        return np.minimum(reach, 1.0)

    def policy_table(self) -> PolicyTable:
        g = self.graph
        nodes = np.flatnonzero(g.kind[: g.n] == EXPANDED)
        lower_q = self.action_values(nodes, g.lower, True)
        strict_q = self.action_values(nodes, g.strict, None)
        upper_q = self.action_values(nodes, g.upper, False)
        # argmax of L, ties broken by the strict-label value, then by U (then the first slot): the
        # policy whose value `lower` is.
        best_lower = lower_q.max(axis=1, keepdims=True)
        tied = lower_q >= best_lower
        best_strict = np.where(tied, strict_q, -np.inf).max(axis=1, keepdims=True)
        score = np.where(tied & (strict_q >= best_strict), upper_q, -np.inf)
        action = score.argmax(axis=1)
        return PolicyTable(t=g.level[nodes], x=g.x[nodes], q=g.q[nodes], beliefs=g.belief[nodes],
                           action=action)


def automatic_suffix_length(n_changing: int) -> int:
    """Longest suffix k with at most CELL_BUDGET words of exactly k belief-changing symbols."""
    if n_changing <= 1:
        return 8
    k = 1
    while n_changing ** (k + 1) <= CELL_BUDGET and k < 8:
        k += 1
    return k


def _bounded_search(tables: ProductTables, belief_rule: BeliefRule, horizon: int | None, tau: float,
                    suffix_length: int, batch: int, started: float, deadline: float,
                    unbounded_value: np.ndarray | None = None, abstraction: Abstraction | None = None,
                    on_iteration: Callable[[float, float], None] | None = None,
                    ) -> tuple[float, float, PolicyTable, dict]:
    """One AO*-style search; returns (lower, upper, table, stats).

    horizon H: P(accepted within H junctions). None: the unbounded problem, nodes deeper than
    UNBOUNDED_DEPTH left open with the unbounded abstraction's bound `unbounded_value`.
    """
    search = _Search(tables, belief_rule, horizon, suffix_length, started, deadline, unbounded_value,
                     abstraction)
    g = search.graph
    roots = search.roots()

    def root_bounds() -> tuple[float, float]:
        return float(g.lower[roots].min()), float(g.upper[roots].max())

    depth_cap = horizon if horizon is not None else UNBOUNDED_DEPTH
    iterations = 0
    expanded = 0
    while np.subtract(*root_bounds()[::-1]) > tau and time.perf_counter() < deadline:
        reach = search.reach(roots)
        frontier = np.flatnonzero((g.kind[: g.n] == FRONTIER) & (g.level[: g.n] < depth_cap))
        weight = reach[frontier] * (g.upper[frontier] - g.lower[frontier])
        if not (weight > 0).any():
            weight = search.reach(roots, every_action=True)[frontier] * (
                g.upper[frontier] - g.lower[frontier])
        positive = weight > 0
        frontier, weight = frontier[positive], weight[positive]
        if frontier.size == 0:
            break
        order = np.argsort(-weight, kind="stable")
        covered = np.cumsum(weight[order])
        count = int(np.searchsorted(covered, 0.5 * covered[-1])) + 1
        chosen = frontier[order[: max(1, min(count, batch))]]
        search.expand(chosen)
        expanded += chosen.size
        search.backup()
        iterations += 1
        if on_iteration is not None:
            on_iteration(*root_bounds())
    search.backup()
    lower, upper = root_bounds()
    table = search.policy_table()
    open_nodes = g.kind[: g.n] == FRONTIER
    stats = {
        "horizon": horizon,
        "suffix_length": suffix_length,
        "abstract_cells": search.cells.n_cells,
        "abstraction_seconds": search.abstraction_seconds,
        "abstraction_bound": search.bound_note,
        "abstraction_root_upper": float(search.frontier_upper(
            0, g.x[roots], g.q[roots], g.cell[roots]).max()),
        "root_dfa_states": g.q[roots].tolist(),
        "threshold_alternates": int(g.alternates_of(None)[0].size),
        # the returned policy's value with labels read strictly (this machine's labeller) from the
        # root the vehicle is in: a lower bound of what `evaluate` measures
        "lower_strict_labels": float(g.strict[roots[0]]),
        "nodes": int(g.n),
        "expanded_nodes": int(expanded),
        "open_frontier_nodes": int(open_nodes.sum()),
        "open_frontier_mass_upper_policy": float(search.reach(roots)[open_nodes].sum()),
        "iterations": iterations,
        "policy_rows": table.rows,
        "lower": lower,
        "upper": upper,
    }
    return lower, upper, table, stats


def bounded_suffix_length(tables: ProductTables, n_changing: int, automatic: int, horizon: int) -> int:
    """Longest k <= automatic whose bounded abstraction, (H + 1) * n_x * n_q * cells(k) floats,
    fits BOUNDED_ENTRY_BUDGET."""
    k = 0
    while k < automatic:
        cells = sum(n_changing ** j for j in range(k + 2))
        if (horizon + 1) * tables.n_x * tables.n_q * cells > BOUNDED_ENTRY_BUDGET:
            break
        k += 1
    return k


def unbounded_suffix_length(tables: ProductTables, n_changing: int, automatic: int) -> int:
    """Longest k <= automatic with n_x * n_q * cells(k) <= UNBOUNDED_STATE_BUDGET (the explicit MDP
    of end_components.py has about (n_symbols + 1) times as many states)."""
    k = 0
    while k < automatic:
        cells = sum(n_changing ** j for j in range(k + 2))
        if tables.n_x * tables.n_q * cells > UNBOUNDED_STATE_BUDGET:
            break
        k += 1
    return k


def synthesize(pomdp: TrustPOMDP, spec: Spec, tau: float = 1e-3, time_limit: float = 60.0,
               horizon: int | None = None, belief_rule: BeliefRule = "bayes",
               suffix_length: int | None = None,
               batch: int = DEFAULT_BATCH,
               on_iteration: Callable[[float, float], None] | None = None) -> SynthesisResult:
    """Maximal probability of satisfying `spec` from (spec.start, initial belief), with a policy.

    horizon: at most this many junctions (None: unbounded). belief_rule: the AV's filter and the
    belief MDP's dynamics ("bayes", or the authors' "paper" update with observation probabilities
    b·P(o|θ) of that belief). Returns lower <= Pr_max <= upper with lower the value of the returned
    policy; stops when upper - lower <= tau or after about time_limit seconds.

    Unbounded: lower is the best P(accepted within H junctions) of bounded searches with growing H
    (UNBOUNDED_HORIZONS): a policy accepting within H with probability L satisfies the unbounded spec
    with probability >= L. upper is the unbounded abstraction's bound, tightened by a search of the
    unbounded problem when a gap remains. on_iteration(lower, upper): called after every expansion
    round with the current search's root bounds (progress bars).
    """
    if tau <= 0:
        raise ValueError("tau must be positive")
    if horizon is not None and horizon < 0:
        raise ValueError("horizon must be >= 0")
    if belief_rule not in ("bayes", "paper"):
        raise ValueError(f"unknown belief rule {belief_rule!r}; use 'bayes' or 'paper'")
    started = time.perf_counter()
    # The last few per cent are kept for the work after the deadline check (final backup, the
    # policy table, the stats), so that the whole call ends within the limit.
    deadline = started + (1.0 - FINISH_SHARE) * time_limit
    tables = build_product(pomdp, spec)
    if suffix_length is None:
        n_changing = observation_symbols(pomdp, belief_rule).n_changing
        suffix_length = automatic_suffix_length(n_changing)
        if horizon is not None:
            suffix_length = bounded_suffix_length(tables, n_changing, suffix_length, horizon)
    distance = acceptance_distance(tables)
    b0 = np.asarray(pomdp.initial_belief, dtype=float)[None, :]
    _, either0 = tables.labeller.belief_margins(b0)
    q0 = {tables.initial_q} | ({int(q) for q in tables.next_q[tables.dfa.initial, tables.start]}
                               if either0.any() else set())
    shortest = int(min(distance[tables.start, q] for q in q0))
    never = shortest > tables.n_x * tables.n_q      # unreachable in the road x DFA graph
    if never or (horizon is not None and shortest > horizon):
        # Answered by graph distance alone: no route accepts within H junctions, whatever the labels.
        table = PolicyTable(t=[], x=[], q=[], beliefs=np.zeros((0, pomdp.n_trust)), action=[])
        lower = upper = 0.0
        note = ("graph distance: acceptance is unreachable" if never else
                f"graph distance: acceptance needs at least {shortest} junctions")
        runs = [{"horizon": horizon, "lower": 0.0, "upper": 0.0, "nodes": 0, "abstraction_root_upper": 0.0,
                 "abstraction_bound": note, "threshold_alternates": 0, "lower_strict_labels": 0.0}]
        if horizon is None:
            note = "graph distance: acceptance is unreachable"
    elif horizon is not None:
        lower, upper, table, stats = _bounded_search(tables, belief_rule, horizon, tau, suffix_length,
                                                     batch, started, deadline, on_iteration=on_iteration)
        runs = [stats]
    else:
        symbols = observation_symbols(pomdp, belief_rule)
        k = unbounded_suffix_length(tables, symbols.n_changing, suffix_length)
        abstraction = build_abstraction(tables, symbols, suffix_cells(symbols, k))
        bound = unbounded_bound(abstraction, started + UNBOUNDED_BOUND_SHARE * time_limit)
        note = (f"suffix length {k}: {bound.end_components} end components collapsed, "
                f"{bound.iterations} iterations from above and below (largest remaining gap "
                f"{bound.gap:.2e}; every iterate from above is sound)" if bound.complete else
                "end-component bound stopped by the time limit: 1 wherever acceptance is possible")
        value = np.minimum(bound.value, 1.0)
        upper = float(max(value[tables.start, q, 0] for q in q0))
        # Bounded horizons give L (a policy accepting within H junctions with probability L
        # satisfies the unbounded spec with probability >= L); each uses the bounded abstraction of
        # the automatic suffix length (capped by the unbounded bound when the cells are the same).
        # After the first, the unbounded problem itself is searched for a quarter of the time left
        # (open nodes valued by the bound): that lowers U where the bound is loose.
        lower, table, runs = -1.0, None, []
        for depth in UNBOUNDED_HORIZONS:
            if upper - lower <= tau or (runs and time.perf_counter() >= deadline):
                break
            k_run = bounded_suffix_length(tables, symbols.n_changing, suffix_length, depth)
            shared = k_run == k
            run_lower, _, run_table, stats = _bounded_search(
                tables, belief_rule, depth, 0.5 * tau, k_run, batch, started, deadline,
                value if shared else None, abstraction if shared else None, on_iteration=on_iteration)
            runs.append(stats)
            if run_lower > lower:
                lower, table = run_lower, run_table
            if len(runs) == 1 and upper - lower > tau:
                remaining = max(deadline - time.perf_counter(), 0.0)
                run_lower, run_upper, run_table, stats = _bounded_search(
                    tables, belief_rule, None, tau, k, batch, started,
                    time.perf_counter() + 0.25 * remaining, value, abstraction, on_iteration=on_iteration)
                stats["end_component_seconds"] = bound.seconds
                runs.append(stats)
                upper = min(upper, run_upper)
                if run_lower > lower:
                    lower, table = run_lower, run_table
        lower = max(lower, 0.0)
    policy = BeliefTablePolicy(table, pomdp.town, spec, lower=lower, upper=upper, horizon=horizon)
    stats = {
        "method": "AO*-style expansion of the product belief MDP with suffix-abstraction upper bounds",
        "belief_rule": belief_rule,
        "converged": bool(upper - lower <= tau),
        "tau": tau,
        "runs": runs,
        "policy_rows": table.rows,
    }
    if horizon is None:
        stats["unbounded_upper"] = note
        stats["lower_from_horizon"] = max(runs, key=lambda r: r["lower"])["horizon"]
    return SynthesisResult(policy=policy, lower=lower, upper=upper,
                           seconds=time.perf_counter() - started, stats=stats, horizon=horizon,
                           belief_rule=belief_rule)
