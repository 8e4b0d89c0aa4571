"""The anytime refinement of one belief-MDP search (AO*/HSVI style), and the closing of the
returned policy's open nodes after it.

Per round: expand the open nodes carrying the most of the root's gap — reach probability under
the upper-greedy policy times (U - L) — and look ahead along their upper-greedy moves; bound
(Bayes) or free-expand (authors' rule) the FRONTIER nodes the returned policy reaches; until
U - L <= tau at the root, the frontier is exhausted, the settings' node budget is reached, or the deadline.
After the last round the completions the policy reaches are bounded (Bayes) or closed (authors'
rule), so L is a lower bound of that policy's value (its exact value when closed exactly).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from trustroute.policies.belief.product_mdp import ProductTables
from trustroute.policies.routing.aware_table import PolicyTable
from trustroute.policies.synthesis.belief_graph import FREE, FRONTIER
from trustroute.policies.synthesis.budget import TimeBudget
from trustroute.policies.synthesis.expansion import UNBOUNDED_DEPTH, BeliefSearch
from trustroute.policies.synthesis.policy_extraction import policy_table
from trustroute.policies.synthesis.result import SearchRun, SynthesisStats
from trustroute.policies.synthesis.settings import SynthesisSettings
from trustroute.policies.synthesis.upper_bound import Abstraction

MIN_BATCH = 64
LOOKAHEAD = 3      # further expansion steps per round along the upper-greedy moves
FULL_SHARE = 0.5   # share of the gap-weighted frontier fully expanded per round
FREE_SHARE = 1.0   # share of the policy's open mass free-expanded per round (1: all of it)
COMPLETION_TAIL = 0.05       # open nodes left unbounded (L = 0) carry at most this share of tau


def _heaviest(nodes: np.ndarray, weight: np.ndarray, batch: int, share: float = 0.5) -> np.ndarray:
    """The heaviest nodes carrying `share` of the total weight: at least MIN_BATCH (when there are
    that many), at most `batch`."""
    order = np.argsort(-weight, kind="stable")
    covered = np.cumsum(weight[order])
    count = int(np.searchsorted(covered, share * covered[-1])) + 1
    return nodes[order[: max(min(MIN_BATCH, nodes.size), min(count, batch))]]


def _heaviest_prefix(nodes: np.ndarray, weight: np.ndarray, tail: float) -> np.ndarray:
    """`nodes` by decreasing weight, without the lightest ones whose weights sum to at most `tail`."""
    order = np.argsort(-weight, kind="stable")
    left = np.cumsum(weight[order][::-1])[::-1]          # weight from each position on
    return nodes[order[left > tail]]


def _root_bounds(search: BeliefSearch, roots: np.ndarray) -> tuple[float, float]:
    """(L, U) at the root: the minimum L and the maximum U over the root nodes."""
    g = search.graph
    return float(g.lower[roots].min()), float(g.upper[roots].max())


def close_completions(search: BeliefSearch, roots: np.ndarray, depth_cap: int, deadline: float) -> bool:
    """Free-expand FRONTIER nodes reached by the returned policy, or by the trust-free route
    from the root, until there are none (True) or the deadline or the node budget comes first
    (False: L is then a lower bound of the policy's value). Then L is the
    policy's exact value (every node it reaches without a row is valued by the completion it
    drives there), and L at the root is at least the trust-free route's value (along that
    route's tree every node is closed, and an EXPANDED node's L is at least its free move's)."""
    g = search.graph
    budget = TimeBudget.until(deadline)
    while True:
        reach = search.reach_lower(roots) + search.reach_lower(roots, trust_free=True)
        todo = np.flatnonzero((g.kind[: g.n] == FRONTIER) & (g.level[: g.n] < depth_cap)
                              & (reach > 0))
        if todo.size == 0:
            return True
        # Down the free moves without backups in between (the policy's move at a FREE node is
        # the free one whatever the values); then one backup, after which the policy's moves
        # at EXPANDED nodes may have changed, so reach is computed again.
        while todo.size:
            if budget.expired() or g.n >= search.node_budget:
                search.backup()
                return False
            search.expand(todo, free_only=True)
            kids = g.child[todo].ravel()
            kids = np.unique(kids[kids >= 0])
            todo = kids[(g.kind[kids] == FRONTIER) & (g.level[kids] < depth_cap)]
        search.backup()


def close_bounds(search: BeliefSearch, roots: np.ndarray, depth_cap: int, deadline: float,
                 tail: float) -> bool:
    """Give the FRONTIER nodes the returned policy reaches their completion bounds, heaviest
    first, until those left carry at most `tail` of reach times U (True) or the deadline
    comes (False). Nodes left keep L = 0, which is sound."""
    g = search.graph
    budget = TimeBudget.until(deadline)
    while True:
        reach = search.reach_lower(roots)
        todo = np.flatnonzero((g.kind[: g.n] == FRONTIER) & ~g.completed[: g.n]
                              & (g.level[: g.n] < depth_cap) & (reach > 0))
        todo = _heaviest_prefix(todo, reach[todo] * g.upper[todo], tail)
        todo = np.concatenate([todo, np.array(search.binding, dtype=np.int64)])
        if todo.size == 0:
            return True
        if budget.expired():
            return False
        search.complete(todo, deadline)
        search.backup()


def _expand_heaviest(search: BeliefSearch, roots: np.ndarray, reach: np.ndarray, depth_cap: int,
                     batch: int) -> np.ndarray | None:
    """Full expansion: the open nodes (FRONTIER or FREE) carrying most of the root's gap under
    the upper-greedy policy (every action carrying the full mass once that frontier is closed).
    Returns the expanded nodes (None: no open node carries any gap)."""
    g = search.graph
    shallow = g.level[: g.n] < depth_cap
    frontier = np.flatnonzero(((g.kind[: g.n] == FRONTIER) | (g.kind[: g.n] == FREE)) & shallow)
    weight = reach[frontier] * (g.upper[frontier] - g.lower[frontier])
    if not (weight > 0).any():
        weight = search.reach(roots, every_action=True)[frontier] * (
            g.upper[frontier] - g.lower[frontier])
    positive = weight > 0
    frontier, weight = frontier[positive], weight[positive]
    if frontier.size == 0:
        return None
    chosen = _heaviest(frontier, weight, batch, FULL_SHARE)
    search.expand(chosen)
    return chosen


def _look_ahead(search: BeliefSearch, chosen: np.ndarray, chosen_reach: np.ndarray, depth_cap: int,
                batch: int) -> int:
    """The new children the upper-greedy move of the just-expanded nodes reaches, heaviest first,
    expanded without a full backup in between (fewer rounds on deep optimal policies), LOOKAHEAD
    steps deep. Returns how many nodes were expanded."""
    g = search.graph
    expanded = 0
    for _ in range(LOOKAHEAD):
        chosen, chosen_reach = search.greedy_children(chosen, chosen_reach, depth_cap)
        if chosen.size == 0:
            break
        keep = _heaviest(chosen, chosen_reach * (g.upper[chosen] - g.lower[chosen]), batch,
                         FULL_SHARE)
        chosen_reach = chosen_reach[np.isin(chosen, keep)]
        chosen = chosen[np.isin(chosen, keep)]
        search.expand(chosen)
        expanded += chosen.size
    return expanded


def _value_open_nodes(search: BeliefSearch, reach_policy: np.ndarray, depth_cap: int, batch: int,
                      tau: float, deadline: float) -> None:
    """FRONTIER nodes the returned policy reached before this round's expansion (it drives the
    trust-free completion there), with the most probability times what they could still be
    worth: bounded by the cluster bounds on the free completion, heaviest first, leaving a light
    tail at L = 0; or expanded along the free move (exact completion trees)."""
    g = search.graph
    known = reach_policy.size            # nodes that existed before this round's expansion
    open_nodes = np.flatnonzero((g.kind[:known] == FRONTIER) & (g.level[:known] < depth_cap))
    free_weight = reach_policy[open_nodes] * g.upper[open_nodes]
    positive = free_weight > 0
    if search.completion:
        search.complete(_heaviest_prefix(open_nodes[positive], free_weight[positive],
                                         COMPLETION_TAIL * tau), deadline)
    elif positive.any() and g.n < search.node_budget:
        if FREE_SHARE >= 1.0:
            search.expand(open_nodes[positive], free_only=True)
        else:
            search.expand(_heaviest(open_nodes[positive], free_weight[positive], batch, FREE_SHARE),
                          free_only=True)


def _refine(search: BeliefSearch, roots: np.ndarray, depth_cap: int, batch: int, tau: float,
            deadline: float) -> int | None:
    """One round: full expansion with look-ahead, the open nodes valued, a backup (and the
    completions the hold rule binds on bounded, then another backup). Returns the nodes expanded
    fully (None: nothing left to expand; then nothing changed)."""
    reach = search.reach(roots)
    reach_policy = search.reach_lower(roots)
    chosen = _expand_heaviest(search, roots, reach, depth_cap, batch)
    if chosen is None:
        return None
    expanded = chosen.size + _look_ahead(search, chosen, reach[chosen], depth_cap, batch)
    _value_open_nodes(search, reach_policy, depth_cap, batch, tau, deadline)
    search.backup()
    if search.binding:
        search.complete(np.array(search.binding, dtype=np.int64), deadline)
        search.backup()
    return expanded


def reached_node_budget(stats: object) -> bool:
    """Whether a search run of a synthesis' statistics says it stopped at its node budget
    (SearchRun.stopped): its bounds would not tighten with more time (the runs of other
    syntheses, which have no node budget, never do)."""
    return isinstance(stats, SynthesisStats) and any(
        isinstance(run, SearchRun) and run.stopped == "node budget" for run in stats.runs)


def bounded_search(tables: ProductTables, settings: SynthesisSettings, horizon: int | None,
                   budget: TimeBudget, unbounded_value: np.ndarray | None = None,
                   abstraction: Abstraction | None = None,
                   on_iteration: Callable[[float, float], None] | None = None
                   ) -> tuple[PolicyTable, SearchRun]:
    """One AO*-style search until `budget`'s deadline; returns the policy's table and the run
    (with its root bounds lower and upper).

    horizon H: P(accepted within H junctions). None: the unbounded problem, nodes deeper than
    UNBOUNDED_DEPTH left open with the unbounded abstraction's bound `unbounded_value`.
    `settings.suffix_length` is this search's (not None).
    """
    tau, suffix_length, batch = settings.tau, settings.suffix_length, settings.batch
    assert suffix_length is not None
    search = BeliefSearch(tables, settings, horizon, budget, unbounded_value, abstraction)
    g = search.graph
    roots = search.roots()
    depth_cap = horizon if horizon is not None else UNBOUNDED_DEPTH
    iterations = 0
    expanded = 0
    while (stopped := _stop(search, roots, tau, budget)) is None:
        grown = _refine(search, roots, depth_cap, batch, tau, budget.deadline)
        if grown is None:
            stopped = "frontier closed"
            break
        expanded += grown
        iterations += 1
        if on_iteration is not None:
            on_iteration(*_root_bounds(search, roots))
    search.backup()
    # Close the returned policy's trust-free completions: every open node it reaches is bounded
    # (completion bounds; up to a light tail) or expanded along the free move (exact completion:
    # then L is the policy's exact value). Unless the deadline comes first; L is a lower bound of
    # the policy's value either way. The run's completion_closed says which.
    closed = (close_bounds(search, roots, depth_cap, budget.deadline, COMPLETION_TAIL * tau)
              if search.completion else close_completions(search, roots, depth_cap, budget.deadline))
    table, conflicts = policy_table(search)
    if g.n >= search.node_budget:
        stopped = "node budget"          # (closing the completions may reach it too)
    return table, _search_run(search, roots, suffix_length, closed, conflicts, (expanded, iterations),
                              stopped, table.rows)


def _stop(search: BeliefSearch, roots: np.ndarray, tau: float, budget: TimeBudget) -> str | None:
    """What ends the refinement before its next round (SEARCH_STOPS), if anything."""
    if np.subtract(*_root_bounds(search, roots)[::-1]) <= tau:
        return "convergence"
    if budget.expired():
        return "deadline"
    if search.graph.n >= search.node_budget:
        return "node budget"
    return None


def _search_run(search: BeliefSearch, roots: np.ndarray, suffix_length: int, closed: bool,
                conflicts: int, rounds: tuple[int, int], stopped: str, rows: int) -> SearchRun:
    """The statistics of a finished search (of horizon `search.horizon`); rounds: the nodes
    expanded fully and the refinement's iterations."""
    expanded, iterations = rounds
    g = search.graph
    lower, upper = _root_bounds(search, roots)
    open_nodes = g.kind[: g.n] == FRONTIER
    return SearchRun(
        horizon=search.horizon, suffix_length=suffix_length, abstract_cells=search.cells.n_cells,
        abstraction_seconds=search.abstraction_seconds,
        abstraction_clock_seconds=search.abstraction_clock_seconds, abstraction_bound=search.bound_note,
        abstraction_root_upper=float(search.frontier_upper(0, g.x[roots], g.q[roots],
                                                           g.cell[roots]).max()),
        root_dfa_states=tuple(g.q[roots].tolist()),
        lower_strict_labels=float(g.strict[roots[0]]), completion_closed=closed,
        completion_bounds=bool(search.completion), free_tree_leaves=search.tree_leaves,
        completion_seconds=search.completion_seconds, completion_clusters=search.completion_clusters,
        compressed=None if search.macro_width is None else search.events is not None,
        macro_width=search.macro_width, row_conflicts=conflicts, nodes=int(g.n),
        expanded_nodes=int(expanded), open_frontier_nodes=int(open_nodes.sum()),
        open_frontier_mass_upper_policy=float(search.reach(roots)[open_nodes].sum()),
        iterations=iterations, stopped=stopped, policy_rows=rows, lower=lower, upper=upper)
