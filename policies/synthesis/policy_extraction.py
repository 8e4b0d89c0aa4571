"""The returned policy's table rows from a finished belief-MDP search (expansion.py).

The policy takes at every EXPANDED node the move the last backup chose (the action maximising L
among those the hold rule allows; ties: strict value, then U) and drives the free completion
everywhere else (the exact-belief acting rule of policies.routing.aware_table.BeliefTablePolicy).
With the event graph's macro moves the rows are laid out junction by junction along the moves'
paths (docs/synthesis.md, "The event graph").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from trustroute.policies.routing.aware_table import PolicyTable
from trustroute.policies.synthesis.belief_graph import EXPANDED, FREE
from trustroute.policies.synthesis.event_graph import EventGraph
from trustroute.policies.synthesis.expansion import BeliefSearch


def policy_table(search: BeliefSearch) -> tuple[PolicyTable, int]:
    """The EXPANDED nodes' moves as the last backup chose them (the moves L was computed
    with: recomputing the move values could differ in the last bit and flip a tie or the hold
    rule's comparison); and the row conflicts of junction_table (0 without macro moves)."""
    g = search.graph
    parts = [(lv.nodes, move) for level in sorted(search.moves) for lv, _, move in search.moves[level]
             if lv is search.levels.get(level)]
    nodes = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, dtype=np.int64)
    action = np.concatenate([p[1] for p in parts]) if parts else np.zeros(0, dtype=np.int64)
    assert nodes.size == int((g.kind[: g.n] == EXPANDED).sum())
    if search.events is not None and not search.events.chains_only:
        return junction_table(search, search.events, nodes, action, g.lower[nodes])
    # plain, or chains: a move is a junction slot, and the roads down a chain have one
    # junction each (no row needed), so the rows are the expanded nodes' own
    return PolicyTable(t=g.level[nodes], x=g.x[nodes], q=g.q[nodes], beliefs=g.belief[nodes],
                       action=action, projected=g.p[nodes]), 0


@dataclass(frozen=True)
class _Contexts:
    """Candidate rows per context (t, road, q, p, belief bytes) of junction_table."""

    best: dict[tuple, tuple[float, int, int]] = field(default_factory=dict)  # (L, -rank, slot) of the winner
    slots: dict[tuple, set[int]] = field(default_factory=dict)  # slots the context's candidates take
    has_row: set[tuple] = field(default_factory=set)            # contexts a policy row passes

    def offer(self, key: tuple, candidate_value: float, here: int, slot: int) -> None:
        score = (candidate_value, -here, slot)
        self.slots.setdefault(key, set()).add(slot)
        if here < 2:
            self.has_row.add(key)
        if key not in self.best or score[:2] > self.best[key][:2]:
            self.best[key] = score


def _offer_path(search: BeliefSearch, contexts: _Contexts, single: np.ndarray, node: int, route: tuple,
                candidate_value: float, rank: int) -> None:
    """Offer the roads of `route` from `node` (rank 0: the node's own move, 2: a FREE node's
    trust-free completion; roads after the first of a row's path rank 1)."""
    g = search.graph
    t0, q, p = int(g.level[node]), int(g.q[node]), int(g.p[node])
    belief = g.belief[node].tobytes()
    for i, (road, slot) in enumerate(route):
        if search.horizon is not None and t0 + i >= search.horizon:
            break
        if single[road]:        # one junction: no choice, no row needed
            continue
        contexts.offer((t0 + i, road, q, p, belief), candidate_value,
                       rank if rank == 2 or i == 0 else 1, slot)


def junction_table(search: BeliefSearch, events: EventGraph, nodes: np.ndarray, action: np.ndarray,
                   value: np.ndarray) -> tuple[PolicyTable, int]:
    """The policy's rows junction by junction from its macro moves (docs/synthesis.md, "The
    event graph"): a row per road of the chosen move's path, at the junction count the vehicle
    is there, with the node's q, p and belief (none of them moves on quiet roads).

    Paths of different nodes can cross at the same context (t, road, q, p, belief); a context
    then takes the candidate with the largest L (a node's own row, then passing paths, then the
    trust-free completion of a FREE node passing there). Every candidate's L is a lower bound
    of following it, so the policy is worth at least L. Also returns how many contexts had
    candidates of different slots (the run's row_conflicts)."""
    g = search.graph
    contexts = _Contexts()
    single = (search.tables.successors >= 0).sum(axis=1) == 1
    for node, a, v in zip(nodes.tolist(), action.tolist(), value.tolist(), strict=True):
        moves = events.moves(int(g.x[node]), int(g.q[node]), int(g.p[node]))
        _offer_path(search, contexts, single, node, moves.path[a], v, 0)
    for node in np.flatnonzero(g.kind[: g.n] == FREE).tolist():
        moves = events.moves(int(g.x[node]), int(g.q[node]), int(g.p[node]))
        _offer_path(search, contexts, single, node, moves.path[moves.free], float(g.lower[node]), 2)
    conflicts = sum(1 for taken in contexts.slots.values() if len(taken) > 1)
    # A context only free completions pass needs no row (the policy drives them there anyway;
    # they all take the free completion's slot of (road, q, p)).
    keys = [key for key in contexts.best if key in contexts.has_row]
    beliefs = (np.array([np.frombuffer(key[4], dtype=float) for key in keys]) if keys
               else np.zeros((0, g.belief.shape[1])))
    out_t, out_x, out_q, out_p = (np.array([key[j] for key in keys], dtype=np.int64) for j in range(4))
    out_a = np.array([contexts.best[key][2] for key in keys], dtype=np.int64)
    return PolicyTable(t=out_t, x=out_x, q=out_q, beliefs=beliefs, action=out_a,
                       projected=out_p), conflicts
