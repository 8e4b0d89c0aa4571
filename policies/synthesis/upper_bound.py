"""Sound upper bounds on the product value from the suffix abstraction of belief space.

The abstract state is (x, q, cell). Abstract Bellman operator (docs/model.md, "What L and U mean"):

    Ū(x, q, c) = max_a max_{v vertex of P_c} Σ_o P(o | v) max_{q' ∈ Q'} Ū(x', q', next_cell(c, o))

with Q' the DFA successors over every label value possible on f_o(P_c) (a belief atom mixed on
the image resolves both ways, optimistically). Σ_o P(o|b) Ū_o is linear in b, so its max over the
polytope P_c is attained at a vertex; with the true belief always inside its cell, induction gives
V*(x, q, b) ≤ Ū(x, q, cell(b)) for every belief of every history.

Horizon H: Ū_H = [q accepting], Ū_t = T̄ Ū_{t+1} (exact backward induction on the abstraction).
Unbounded: every iterate T̄^n(1) is an upper bound of the true value (V* = T V* ≤ T̄ V* ≤ T̄^n 1 by
monotonicity), but the iteration converges to the greatest fixed point, which end components that
never accept can hold above the least one. `unbounded_upper` starts from 0 on states that cannot
reach acceptance at all (can_accept, a graph analysis) and from 1 elsewhere, and returns the last
iterate: sound, exact where acceptance is unreachable, possibly loose on end components from which
acceptance is reachable but not forced. Synthesis uses policies/synthesis/end_components.py
instead, which collapses end components and converges to the least fixed point.

The abstraction's size: cells are the last k belief-changing symbols, k chosen by
automatic_suffix_length (CELL_BUDGET words) and capped by what the bounded abstraction
(bounded_suffix_length) or the explicit unbounded MDP (unbounded_suffix_length) may hold.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import overload

import numpy as np

from trustroute.policies.belief.product_mdp import ProductTables
from trustroute.policies.routing.free import label_free_distance
from trustroute.policies.synthesis.belief_cells import ObservationSymbols, SuffixCells, image_label_status
from trustroute.policies.synthesis.budget import TimeBudget
from trustroute.policies.work_clock import now as clock_now
from trustroute.policies.work_clock import spend

BACKUP_CHUNK_ENTRIES = 4_000_000   # floats of one chunk of the vectorised backup (32 MB)
CELL_BUDGET = 5000          # automatic suffix length: the longest k with n_symbols**k <= this
BOUNDED_ENTRY_BUDGET = 20_000_000   # floats of the bounded abstraction (160 MB)
UNBOUNDED_STATE_BUDGET = 20_000
ENTRIES_PER_UNIT = 25        # abstraction entries backed up per unit of work (policies/work_clock.py)


@dataclass(frozen=True, eq=False)
class Abstraction:
    tables: ProductTables
    symbols: ObservationSymbols
    cells: SuffixCells
    possible_bits: np.ndarray     # bool [n_cells, n_symbols, 2**n_atoms]
    vertex_likelihood: np.ndarray  # [n_symbols, n_trust (vertex), n_cells]: P(o | vertex v of cell c)
    # [n_symbols, n_cells]: max_v P(o | vertex v of cell c), for incidents with one symbol (see
    # abstract_backup)
    best_vertex_likelihood: np.ndarray


def build_abstraction(tables: ProductTables, symbols: ObservationSymbols, cells: SuffixCells
                      ) -> Abstraction:
    m = len(tables.belief_atom_names)
    possible = np.ones((cells.n_cells, symbols.n_symbols, 2 ** m), dtype=bool)
    statuses = image_label_status(cells, symbols, tables.belief_coeffs, tables.belief_offsets)
    for j, status in enumerate(statuses):
        bit = (np.arange(2 ** m) >> j) & 1                                # [β]
        possible &= (status[:, :, None] == 2) | (status[:, :, None] == bit[None, None, :])
    vertex_likelihood = np.ascontiguousarray(
        np.einsum("cvk,ok->ovc", cells.vertices, symbols.likelihood))
    return Abstraction(tables=tables, symbols=symbols, cells=cells, possible_bits=possible,
                       vertex_likelihood=vertex_likelihood,
                       best_vertex_likelihood=vertex_likelihood.max(axis=1))


@overload
def abstract_backup(abstraction: Abstraction, value_next: np.ndarray, deadline: None = None) -> np.ndarray:
    ...


@overload
def abstract_backup(abstraction: Abstraction, value_next: np.ndarray,
                    deadline: float | None) -> np.ndarray | None:
    ...


def abstract_backup(abstraction: Abstraction, value_next: np.ndarray,
                    deadline: float | None = None) -> np.ndarray | None:
    """One application of T̄ to value_next [n_x, n_q, n_cells]; terminal DFA states fixed.
    None if `deadline` passes before it is complete.

    The value of moving to road x2 does not depend on the road x it is entered from, so it is
    computed once per destination road (in chunks of roads sharing an incident, vectorised over
    DFA states and cells) and each road then takes the max over its successors.
    """
    tables, symbols, cells = abstraction.tables, abstraction.symbols, abstraction.cells
    n_x, n_q, n_c = value_next.shape
    live = np.flatnonzero(~(tables.accepting | tables.rejecting))
    out = np.zeros_like(value_next)
    out[:, tables.accepting, :] = 1.0
    if live.size == 0:
        return out
    n_vertices = cells.vertices.shape[1]
    entered = np.zeros((n_x, live.size, n_c))          # value of entering road x2, per (q, cell)
    chunk = max(1, BACKUP_CHUNK_ENTRIES // max(1, live.size * n_c * n_vertices))
    road_incident = tables.pomdp.road_incident
    for incident, members in enumerate(symbols.by_incident):
        roads = np.flatnonzero(road_incident == incident)
        for start in range(0, roads.size, chunk):
            if deadline is not None and clock_now() > deadline:
                return None
            x2 = roads[start:start + chunk]
            spend(1 + x2.size * live.size * n_c * len(members) // ENTRIES_PER_UNIT)
            branches = [_branch(abstraction, value_next, live, x2, o) for o in members]
            if len(members) == 1:
                # one symbol: max_v P(o | v)·value is (max_v P(o | v))·value exactly, as rounding
                # a product with a factor >= 0 is monotone in the other factor
                entered[x2] = abstraction.best_vertex_likelihood[members[0]][None, None, :] * branches[0]
                continue
            # Σ_o P(o | v) value_o per vertex v of each cell, then the max over the vertices
            # (vertex axis first: a max over a short last axis is several times slower)
            per_vertex = np.zeros((n_vertices, x2.size, live.size, n_c))
            term = np.empty_like(per_vertex)
            for o, branch in zip(members, branches, strict=True):
                per_vertex += np.multiply(abstraction.vertex_likelihood[o][:, None, None, :], branch[None],
                                          out=term)
            entered[x2] = per_vertex.max(axis=0)
    # each road's best successor, one successor slot at a time (a max is exact in any order; a
    # road without a successor keeps 0)
    best = np.zeros_like(entered)
    for slot in tables.successors.T:
        legal = slot >= 0
        if legal.any():
            successor = entered[np.maximum(slot, 0)]
            successor[~legal] = 0.0
            np.maximum(best, successor, out=best)
    out[:, live, :] = np.minimum(best, 1.0)
    return out


def _branch(abstraction: Abstraction, value_next: np.ndarray, live: np.ndarray, x2: np.ndarray,
            o: int) -> np.ndarray:
    """[roads x2, live q, cells]: the value after reading symbol o on entering x2, the best over
    the belief-label values possible on the image of each cell."""
    tables, cells = abstraction.tables, abstraction.cells
    c2 = cells.next_cell[:, o]
    branch = np.zeros((x2.size, live.size, c2.size))
    for bits in range(abstraction.possible_bits.shape[2]):
        allowed = abstraction.possible_bits[:, o, bits]
        if not allowed.any():
            continue
        q2 = tables.next_q[live[:, None], x2[None, :], bits].T              # [roads, n_live]
        candidate = value_next[x2[:, None], q2]                             # [roads, n_live, c]
        if not abstraction.symbols.identity[o]:                             # else c2 is every cell
            candidate = np.take(candidate, c2, axis=2)
        if not allowed.all():   # 0 where the label value is impossible on the cell's image
            np.multiply(candidate, allowed, out=candidate)
        np.maximum(branch, candidate, out=branch)
    return branch


def bounded_upper(abstraction: Abstraction, horizon: int, deadline: float | None = None,
                  cap: np.ndarray | None = None) -> np.ndarray:
    """Ū_t for t = 0..H as [H+1, n_x, n_q, n_cells] (Ū_t bounds P(accept within H - t more junctions)).

    cap: a sound bound valid at every t (e.g. the unbounded one), applied elementwise. If the
    deadline passes, the levels not yet computed get `cap` (or 1 where the DFA state is not
    rejecting): still sound, only looser.
    """
    tables = abstraction.tables
    shape = (tables.n_x, tables.n_q, abstraction.cells.n_cells)
    if cap is None:
        cap = np.broadcast_to(~tables.rejecting[None, :, None], shape).astype(float)
    values = np.zeros((horizon + 1,) + shape)
    values[horizon] = np.broadcast_to(tables.accepting[None, :, None], shape)
    for t in range(horizon - 1, -1, -1):
        backed = abstract_backup(abstraction, values[t + 1], deadline)
        if backed is None:
            values[: t + 1] = cap
            break
        values[t] = np.minimum(backed, cap)
    return values


@dataclass(frozen=True)
class UnboundedUpper:
    value: np.ndarray          # [n_x, n_q, n_cells]
    iterations: int
    last_change: float
    seconds: float


def can_accept(tables: ProductTables) -> np.ndarray:
    """bool [n_x, n_q]: acceptance reachable in the road × DFA graph with belief atoms free.

    An over-approximation of reachability in the product belief MDP (every belief label value
    allowed at every step), so a False here is a sound 0 for the value.
    """
    n_x, n_q = tables.n_x, tables.n_q
    reached = np.zeros((n_x, n_q), dtype=bool)
    reached[:, tables.accepting] = True
    live = ~(tables.accepting | tables.rejecting)
    while True:
        grown = reached.copy()
        for x in range(n_x):
            for x2 in tables.successors[x]:
                if x2 < 0:
                    continue
                # q can reach acceptance via x2 if some label value leads to a reaching state.
                grown[x] |= live & reached[x2][tables.next_q[:, x2, :]].any(axis=1)
        if (grown == reached).all():
            return reached
        reached = grown


def acceptance_distance(tables: ProductTables) -> np.ndarray:
    """int [n_x, n_q]: fewest junctions from (x, q) to an accepting DFA state in the road × DFA
    graph with every belief-label value allowed (a breadth-first search backwards from acceptance;
    a large sentinel where acceptance is unreachable). A lower bound on the junctions any policy
    needs, so a node with distance > the junctions left is worth exactly 0."""
    return label_free_distance(tables.successors, tables.next_q, tables.accepting, tables.rejecting)


def unbounded_upper(abstraction: Abstraction, time_limit: float, tolerance: float = 1e-6,
                    max_iterations: int = 2000) -> UnboundedUpper:
    """Iterate T̄ from 1 (every iterate is sound; see the module docstring) until it stalls.

    States that cannot reach acceptance at all (can_accept) start at 0, which removes the
    greatest-fixed-point excess on end components from which acceptance is unreachable.
    """
    budget = TimeBudget.start(time_limit)
    tables = abstraction.tables
    shape = (tables.n_x, tables.n_q, abstraction.cells.n_cells)
    value = np.broadcast_to(can_accept(tables)[:, :, None], shape).astype(float)
    change = np.inf
    iterations = 0
    while iterations < max_iterations and not budget.expired():
        new = np.minimum(value, abstract_backup(abstraction, value))
        change = float(np.abs(new - value).max())
        value = new
        iterations += 1
        if change <= tolerance:
            break
    return UnboundedUpper(value=value, iterations=iterations, last_change=change,
                          seconds=budget.elapsed())


def automatic_suffix_length(n_changing: int) -> int:
    """Longest suffix k with at most CELL_BUDGET words of exactly k belief-changing symbols."""
    if n_changing <= 1:
        return 8
    k = 1
    while n_changing ** (k + 1) <= CELL_BUDGET and k < 8:
        k += 1
    return k


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
