"""How the belief-MDP search values its open nodes, and the rule that keeps that sound.

Under the Bayes rule an open (FRONTIER) node's L is a lower bound of the trust-free completion's
value from it: cluster bounds from policies/synthesis/completion_value.py, assigned to the node
store here (`bound_completions`). The completion's upper bound there decides where the returned
policy may leave the free move (the hold rule, `held_choice`; docs/synthesis.md, "Open nodes and
the acting rule"); `free_touched` finds the keys that rule applies at. Elsewhere open nodes are
valued by exact trees along the free moves, whose size `completion_tree_leaves` estimates.
"""

from __future__ import annotations

import numpy as np

from trustroute.policies.belief.product_mdp import ProductTables
from trustroute.policies.routing.free import StateOnlyTask
from trustroute.policies.synthesis.belief_cells import ObservationSymbols
from trustroute.policies.synthesis.belief_graph import FRONTIER, BeliefGraph
from trustroute.policies.synthesis.budget import TimeBudget
from trustroute.policies.synthesis.completion_value import CompletionStarts, FreeRoute, completion_bounds

COMPLETION_CHUNK = 64        # start nodes per batched cluster propagation (memory: ~25 MB each)


def free_touched(graph: BeliefGraph, route: FreeRoute, shape: tuple[int, ...]) -> np.ndarray:
    """bool [level, x, p] of `shape`: keys the free completion can reach, one junction or more
    after a node whose L uses its completion bound (free_lower > 0); belief and DFA state ignored
    (a superset)."""
    g = graph
    touched = np.zeros(shape, dtype=bool)
    source = np.flatnonzero(g.completed[: g.n] & (g.free_lower[: g.n] > 0))
    start = np.zeros_like(touched)
    start[g.level[source], g.x[source], g.p[source]] = True
    road, task = route.next_road, route.next_task
    carried = np.zeros(touched.shape[1:], dtype=bool)
    for level in range(touched.shape[0] - 1):
        carried = carried | start[level]
        nxt = np.zeros_like(carried)
        xs, ps = np.nonzero(carried)
        nxt[road[xs, :, ps].ravel(), task[xs, :, ps].ravel()] = True     # every DFA state
        touched[level + 1] = nxt
        carried = nxt
    return touched


def bound_completions(graph: BeliefGraph, tables: ProductTables, symbols: ObservationSymbols,
                      route: FreeRoute, nodes: np.ndarray, depth_cap: int, deadline: float) -> int:
    """Cluster bounds on the free completion's value from `nodes` (completion_value.py):
    free_lower (a FRONTIER node's L and strict value) and free_upper, chunk by chunk until the
    deadline. Returns the largest number of clusters a chunk held (0: none bounded)."""
    g = graph
    nodes = nodes[~g.completed[nodes]]
    budget = TimeBudget.until(deadline)
    clusters = 0
    for begin in range(0, nodes.size, COMPLETION_CHUNK):
        if budget.expired():
            break
        chunk = nodes[begin:begin + COMPLETION_CHUNK]
        starts = CompletionStarts(g.x[chunk], g.q[chunk], g.p[chunk], g.belief[chunk],
                                  depth_cap - g.level[chunk])
        bounds = completion_bounds(tables, symbols, route, starts, deadline)
        # (stopped by the deadline, the chunk's bounds are sound but loose; they are kept, as
        # the node is marked completed, since nothing runs after the deadline to redo them)
        g.free_lower[chunk] = bounds.lower
        g.free_upper[chunk] = np.minimum(g.free_upper[chunk], bounds.upper)
        g.completed[chunk] = True
        frontier = chunk[g.kind[chunk] == FRONTIER]
        g.lower[frontier] = np.maximum(g.lower[frontier], g.free_lower[frontier])
        g.strict[frontier] = np.maximum(g.strict[frontier], g.free_lower[frontier])
        clusters = max(clusters, bounds.clusters)
    return clusters


def completion_tree_leaves(tables: ProductTables, symbols: ObservationSymbols, task: StateOnlyTask,
                           depth_cap: int) -> float:
    """Leaves of the trust-free route's observation tree within `depth_cap` junctions: the product
    of the observation symbols of the incidents on its roads after the start (identity symbols
    count once). Exact completion trees from the search's open nodes are of this order."""
    route = task.completion(tables.spec.start, task.initial_state) or [tables.spec.start]
    town, pomdp = tables.pomdp.town, tables.pomdp
    leaves = 1.0
    for road in route[1: depth_cap + 1]:
        members = symbols.by_incident[int(pomdp.road_incident[town.state_index(road)])]
        leaves *= max(1, sum(1 for o in members if not symbols.identity[o]))
    return leaves


def held_choice(lower_q: np.ndarray, strict_q: np.ndarray, upper_q: np.ndarray, free: np.ndarray,
                held: np.ndarray, free_lower: np.ndarray, free_upper: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The hold rule (BeliefSearch.choose, expansion.py) on move values [nodes, moves]: (move,
    lower_q, strict_q) with the free move's values raised to free_lower; a `held` node leaves its
    `free` move only for a move whose L is at least free_upper; among the allowed moves,
    policy_choice."""
    rows = np.arange(lower_q.shape[0])
    lower_q, strict_q = lower_q.copy(), strict_q.copy()
    lower_q[rows, free] = np.maximum(lower_q[rows, free], free_lower)
    strict_q[rows, free] = np.maximum(strict_q[rows, free], free_lower)
    allowed = ~held[:, None] | (lower_q >= free_upper[:, None])
    allowed[rows, free] = True
    return policy_choice(np.where(allowed, lower_q, -2.0), strict_q, upper_q), lower_q, strict_q


def policy_choice(lower_q: np.ndarray, strict_q: np.ndarray, upper_q: np.ndarray) -> np.ndarray:
    """The returned policy's move per node from its move values [nodes, moves]: argmax of L, ties
    broken by the strict-label value, then by U, then the first slot (the policy whose value
    `lower` is)."""
    best_lower = lower_q.max(axis=1, keepdims=True)
    tied = lower_q >= best_lower
    best_strict = np.where(tied, strict_q, -np.inf).max(axis=1, keepdims=True)
    score = np.where(tied & (strict_q >= best_strict), upper_q, -np.inf)
    return score.argmax(axis=1)

