"""Policy synthesis with certified bounds: lower <= Pr_max(spec) <= upper (DESIGN.md, "Synthesis").

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
  value is at least `lower`. It is a policies.table_policy.BeliefTablePolicy (acts on any belief).

Horizon H: at most H junctions (the study measures "policy, then fallback after 20", so H = 20 is
the natural companion). Unbounded (horizon=None): lower is the best value of bounded searches with
growing H (their policies are policies for the unbounded problem too, worth at least their bounded
value); upper is the abstraction's unbounded bound (abstract_bounds.unbounded_upper), tightened when
it leaves a gap by one search of the unbounded problem itself (open nodes, including those deeper
than UNBOUNDED_DEPTH, valued by that bound).
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
from trustroute.policies.synthesis.upper_bound import bounded_upper, build_abstraction, unbounded_upper

CELL_BUDGET = 5000          # automatic suffix length: the longest k with n_symbols**k <= this
DEFAULT_BATCH = 4096
UNBOUNDED_HORIZONS = (20, 30, 40, 60, 80, 120, 160)
UNBOUNDED_DEPTH = 60

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
        self.kind = np.zeros(capacity, dtype=np.int8)
        self.child = np.full((capacity, n_actions, n_outcomes), -1, dtype=np.int64)
        self.prob = np.zeros((capacity, n_actions, n_outcomes))
        self.memo: list[dict[tuple[int, int, bytes], int]] = []
        self.expanded_by_level: list[list[int]] = []

    def _grow(self, needed: int) -> None:
        capacity = self.level.shape[0]
        if needed <= capacity:
            return
        new = max(needed, 2 * capacity)
        for name in ("level", "x", "q", "cell", "upper", "lower", "kind"):
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
                 started: float, unbounded_value: np.ndarray | None = None) -> None:
        self.tables, self.rule, self.horizon = tables, rule, horizon
        self.started = started
        pomdp = tables.pomdp
        self.symbols = observation_symbols(pomdp, rule)
        self.cells = suffix_cells(self.symbols, suffix_length)
        if horizon is not None:
            abstraction = build_abstraction(tables, self.symbols, self.cells)
            self.bound = bounded_upper(abstraction, horizon)
            self.bound_note = "exact backward induction on the abstraction"
        else:
            assert unbounded_value is not None
            self.bound = [unbounded_value]
            self.bound_note = "the unbounded abstraction's bound (abstract_bounds.unbounded_upper)"
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
        g.upper[ids[accepted]] = g.lower[ids[accepted]] = 1.0
        rest = ids[~accepted]
        if rest.size == 0:
            return
        upper = np.minimum(1.0, self.frontier_upper(level, g.x[rest], g.q[rest], g.cell[rest]))
        dead = tables.rejecting[g.q[rest]] | (upper <= 0.0)
        if self.horizon is not None and level >= self.horizon:
            dead[:] = True
        g.kind[rest[dead]] = ZERO
        g.upper[rest[dead]] = 0.0
        g.lower[rest[dead]] = 0.0
        live = rest[~dead]
        g.upper[live] = upper[~dead]
        g.lower[live] = 0.0

    def root(self) -> int:
        tables = self.tables
        b0 = np.asarray(tables.pomdp.initial_belief, dtype=float)[None, :]
        ids, _ = self.graph.add(0, np.array([tables.start]), np.array([tables.initial_q]),
                                np.array([0]), b0)
        self.classify(ids, 0)
        return int(ids[0])

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
            q2 = tables.step(g.q[parent], x2, belief)
            cell2 = self.cells.next_cell[g.cell[parent], symbol]
            ids, new = g.add(level + 1, x2, q2, cell2, belief)
            g.child[parent, slot, self.slot_of_symbol[symbol]] = ids
            g.prob[parent, slot, self.slot_of_symbol[symbol]] = probability
            self.classify(ids[new], level + 1)
            g.kind[parents] = EXPANDED
            g.expanded_by_level[level].extend(members)

    def action_values(self, nodes: np.ndarray, values: np.ndarray) -> np.ndarray:
        g = self.graph
        child = g.child[nodes]
        child_value = np.where(child >= 0, values[np.maximum(child, 0)], 0.0)
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
            g.upper[nodes] = np.minimum(g.upper[nodes], self.action_values(nodes, g.upper).max(axis=1))
            g.lower[nodes] = np.maximum(g.lower[nodes], self.action_values(nodes, g.lower).max(axis=1))

    def reach(self, root: int) -> np.ndarray:
        """Probability of reaching each node under the upper-greedy policy."""
        g = self.graph
        reach = np.zeros(g.n)
        reach[root] = 1.0
        for members in g.expanded_by_level:
            if not members:
                continue
            nodes = np.array(members, dtype=np.int64)
            nodes = nodes[reach[nodes] > 0]
            if nodes.size == 0:
                continue
            best = self.action_values(nodes, g.upper).argmax(axis=1)
            child = g.child[nodes, best]
            mass = reach[nodes, None] * g.prob[nodes, best]
            ok = child >= 0
            np.add.at(reach, child[ok], mass[ok])
        return reach

    def policy_table(self) -> PolicyTable:
        g = self.graph
        nodes = np.flatnonzero(g.kind[: g.n] == EXPANDED)
        lower_q = self.action_values(nodes, g.lower)
        upper_q = self.action_values(nodes, g.upper)
        # argmax of L, ties broken by U (then the first slot): the policy whose value `lower` is.
        best_lower = lower_q.max(axis=1, keepdims=True)
        score = np.where(lower_q >= best_lower, upper_q, -np.inf)
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
                    unbounded_value: np.ndarray | None = None,
                    on_iteration: Callable[[float, float], None] | None = None,
                    ) -> tuple[float, float, PolicyTable, dict]:
    """One AO*-style search; returns (lower, upper, table, stats).

    horizon H: P(accepted within H junctions). None: the unbounded problem, nodes deeper than
    UNBOUNDED_DEPTH left open with the unbounded abstraction's bound `unbounded_value`.
    """
    search = _Search(tables, belief_rule, horizon, suffix_length, started, unbounded_value)
    g = search.graph
    root = search.root()
    depth_cap = horizon if horizon is not None else UNBOUNDED_DEPTH
    iterations = 0
    expanded = 0
    while g.upper[root] - g.lower[root] > tau and time.perf_counter() < deadline:
        reach = search.reach(root)
        frontier = np.flatnonzero((g.kind[: g.n] == FRONTIER) & (g.level[: g.n] < depth_cap))
        weight = reach[frontier] * (g.upper[frontier] - g.lower[frontier])
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
            on_iteration(float(g.lower[root]), float(g.upper[root]))
    search.backup()
    lower, upper = float(g.lower[root]), float(g.upper[root])
    table = search.policy_table()
    open_nodes = g.kind[: g.n] == FRONTIER
    stats = {
        "horizon": horizon,
        "suffix_length": suffix_length,
        "abstract_cells": search.cells.n_cells,
        "abstraction_seconds": search.abstraction_seconds,
        "abstraction_bound": search.bound_note,
        "abstraction_root_upper": float(search.frontier_upper(
            0, np.array([tables.start]), np.array([tables.initial_q]), np.array([0]))[0]),
        "nodes": int(g.n),
        "expanded_nodes": int(expanded),
        "open_frontier_nodes": int(open_nodes.sum()),
        "open_frontier_mass_upper_policy": float(search.reach(root)[open_nodes].sum()),
        "iterations": iterations,
        "policy_rows": table.rows,
        "lower": lower,
        "upper": upper,
    }
    return lower, upper, table, stats


def _unbounded_upper(tables: ProductTables, belief_rule: BeliefRule, suffix_length: int,
                     time_limit: float) -> tuple[np.ndarray, str]:
    symbols = observation_symbols(tables.pomdp, belief_rule)
    cells = suffix_cells(symbols, suffix_length)
    result = unbounded_upper(build_abstraction(tables, symbols, cells), time_limit)
    note = (f"{result.iterations} iterations of the abstract operator (from 0 where acceptance is "
            f"unreachable, 1 elsewhere; last change {result.last_change:.2e}; every iterate is sound)")
    return np.minimum(result.value, 1.0), note


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
    deadline = started + time_limit
    tables = build_product(pomdp, spec)
    if suffix_length is None:
        suffix_length = automatic_suffix_length(observation_symbols(pomdp, belief_rule).n_changing)
    if horizon is not None:
        lower, upper, table, stats = _bounded_search(tables, belief_rule, horizon, tau, suffix_length,
                                                     batch, started, deadline, on_iteration=on_iteration)
        runs = [stats]
    else:
        bound, note = _unbounded_upper(tables, belief_rule, suffix_length, 0.2 * time_limit)
        upper = float(bound[tables.start, tables.initial_q, 0])
        lower, table, runs = -1.0, None, []
        for depth in UNBOUNDED_HORIZONS:
            if runs and time.perf_counter() >= deadline:
                break
            run_lower, _, run_table, stats = _bounded_search(
                tables, belief_rule, depth, 0.5 * tau, suffix_length, batch, started, deadline,
                on_iteration=on_iteration)
            runs.append(stats)
            if run_lower > lower:
                lower, table = run_lower, run_table
            if upper - lower <= tau:
                break
            if len(runs) == 1:
                # The abstraction alone leaves a gap: search the unbounded problem itself, with the
                # abstraction's bound on open nodes, for half the remaining time (tightens upper).
                remaining = deadline - time.perf_counter()
                run_lower, run_upper, run_table, stats = _bounded_search(
                    tables, belief_rule, None, tau, suffix_length, batch, started,
                    time.perf_counter() + 0.5 * max(remaining, 0.0), bound, on_iteration)
                runs.append(stats)
                upper = min(upper, run_upper)
                if run_lower > lower:
                    lower, table = run_lower, run_table
                if upper - lower <= tau:
                    break
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
