"""Expansion and backup of the belief-MDP search (BeliefSearch): the unfolded product belief MDP
as an AND-OR graph (belief_graph.py), its moves, Bellman backups of [L, U], the returned policy's
move per node, and reach probabilities.

A node's children are, per move, the observation symbols with their exact probabilities and exact
Bayes (or "paper") posteriors. FRONTIER (unexpanded) nodes: U = the suffix abstraction's bound at
the node's cell (upper_bound.py; the cell is the node's last k belief-changing symbols, which it
knows exactly); L = a lower bound of the trust-free completion's value from the node
(open_node_bounds.py; 0 until computed). FREE nodes (expanded along the trust-free completion's
move only): L = that move's value, U = the bound. Terminal nodes are exact: accepted 1, rejected 0,
horizon reached 0. EXPANDED nodes: U = min(U, max_a Σ_o p U_child) and L = max_a Σ_o p L_child.

Labels at thresholds: a belief whose label floating point cannot decide is labelled exactly on its
history's word (policies/belief/exact_labels.py); histories merge at a node only where their words
lead to one exact belief (belief_graph.py), so that label is every history's there
(docs/synthesis.md, "Labels at thresholds").
"""

from __future__ import annotations

import time

import numpy as np

from trustroute.core import defaults
from trustroute.policies.belief.exact_labels import exact_labels, symbol_code
from trustroute.policies.belief.product_mdp import ProductTables
from trustroute.policies.routing.free import free_completion, state_only_task
from trustroute.policies.synthesis.belief_cells import apply_symbol, observation_symbols, suffix_cells
from trustroute.policies.synthesis.belief_graph import (
    ACCEPTED,
    EXPANDED,
    FREE,
    FRONTIER,
    ZERO,
    BeliefGraph,
    ExpandedLevel,
)
from trustroute.policies.synthesis.budget import TimeBudget
from trustroute.policies.synthesis.completion_value import FreeRoute
from trustroute.policies.synthesis.event_graph import EventGraph
from trustroute.policies.synthesis.open_node_bounds import (
    bound_completions,
    completion_tree_leaves,
    free_touched,
    held_choice,
    policy_choice,
)
from trustroute.policies.synthesis.settings import SynthesisSettings
from trustroute.policies.synthesis.upper_bound import (
    Abstraction,
    acceptance_distance,
    bounded_upper,
    build_abstraction,
)
from trustroute.policies.work_clock import spend

UNBOUNDED_DEPTH = 60        # the unbounded search leaves nodes this deep open (<= evaluate's cap)
# Most macro moves per context for which the event graph is used: node arrays hold one slot per
# move, so a town whose quiet roads connect many event roads is searched junction by junction.
MAX_MACRO_WIDTH = 16
# How open nodes are valued (settings.py's COMPLETION_MODES): "exact" trees along the free moves
# (L is the returned policy's exact value; the trees grow exponentially with the incident roads
# left on long routes), "bounds"
# (cluster bounds on the completion, completion_value.py; L a lower bound of the policy's value),
# "auto": exact where the trust-free route's own observation tree within the horizon has at most
# AUTO_TREE_LEAVES leaves (completion_tree_leaves), bounds otherwise.
AUTO_TREE_LEAVES = defaults.NODE_BUDGET // 4
# Units of work (policies/work_clock.py): per child an expansion makes, and nodes per unit of a backup
CHILD_UNITS = 16
NODES_PER_UNIT = 2


class BeliefSearch:
    """The search's state: the node store, the abstraction's bound, the moves, the free completion,
    and the moves of the last backup. `budget`: the synthesis' start (abstraction_seconds and
    abstraction_clock_seconds count from it) and this search's deadline (the bounded abstraction
    stops there)."""

    def __init__(self, tables: ProductTables, settings: SynthesisSettings, horizon: int | None,
                 budget: TimeBudget, unbounded_value: np.ndarray | None = None,
                 abstraction: Abstraction | None = None) -> None:
        """`settings.suffix_length` is the search's own (not None); `horizon` may differ from
        `settings.horizon` (the unbounded synthesis runs bounded searches)."""
        rule, suffix_length = settings.belief_rule, settings.suffix_length
        compress, completion = settings.compress, settings.completion
        assert suffix_length is not None
        self.tables, self.rule, self.horizon = tables, rule, horizon
        self.node_budget = settings.node_budget
        pomdp = tables.pomdp
        if abstraction is not None:        # built once per synthesize call and shared by its runs
            self.symbols, self.cells = abstraction.symbols, abstraction.cells
        else:
            self.symbols = observation_symbols(pomdp, rule)
            self.cells = suffix_cells(self.symbols, suffix_length)
        self.distance = acceptance_distance(tables)
        self.labels = exact_labels(pomdp, tables.labeller, rule)
        self.symbol_codes = symbol_code(self.symbols.incident, self.symbols.human_action,
                                        self.symbols.performance)
        if horizon is not None:
            if abstraction is None:
                abstraction = build_abstraction(tables, self.symbols, self.cells)
            self.bound = bounded_upper(abstraction, horizon, budget.deadline, unbounded_value)
            self.bound_note = "exact backward induction on the abstraction"
        else:
            self.bound = np.asarray(unbounded_value)[None]
            self.bound_note = ("the unbounded abstraction's least fixed point from above, end "
                               "components collapsed (policies/synthesis/end_components.py)")
        self.abstraction_seconds = budget.elapsed()
        self.abstraction_clock_seconds = budget.used()
        n_outcomes = max(len(s) for s in self.symbols.by_incident)
        # symbol ids per incident, padded with -1
        self.symbols_of_incident = np.full((len(self.symbols.by_incident), n_outcomes), -1, dtype=np.int64)
        for i, members in enumerate(self.symbols.by_incident):
            self.symbols_of_incident[i, : len(members)] = members
        self.slot_of_symbol = np.zeros(self.symbols.n_symbols, dtype=np.int64)
        for members in self.symbols.by_incident:
            for j, o in enumerate(members):
                self.slot_of_symbol[o] = j
        # The free completion (policies/routing/free.py) as the returned policy drives it wherever
        # it has no row: its move at (road, DFA state, state-only task state), the state-only task's
        # while that is not complete, then the shortest route back to what the DFA still needs,
        # every label allowed (BeliefTablePolicy's exact-belief rule).
        self.task = state_only_task(pomdp.town, tables.spec)
        self.free_slot = free_completion(pomdp.town, tables.spec).slot               # [n_x, n_q, n_p]
        self.next_p = np.asarray(self.task.next_state, dtype=np.int64)               # [n_p, n_x]
        # Moves: macro moves of the event graph (policies/synthesis/event_graph.py) when some road
        # is quiet and the widest context has at most MAX_MACRO_WIDTH of them; else the junctions.
        self.events: EventGraph | None = None
        self.macro_width: int | None = None
        if compress != "off":
            events = EventGraph(tables, self.symbols, self.task, chains_only=compress == "chains",
                                free_slot=self.free_slot)
            if events.compresses and events.width <= MAX_MACRO_WIDTH:
                self.events = events
            self.macro_width = events.width
        n_actions = self.events.width if self.events is not None else tables.successors.shape[1]
        self.graph = BeliefGraph(pomdp.n_trust, n_actions, n_outcomes, self.labels.filter.same_belief)
        self.levels: dict[int, ExpandedLevel] = {}
        self.moves: dict[int, list[tuple[ExpandedLevel, np.ndarray, np.ndarray]]] = {}
        self.free_levels: dict[int, tuple[int, ExpandedLevel]] = {}
        self.depth_cap = horizon if horizon is not None else UNBOUNDED_DEPTH
        # Bayes rule: open nodes are valued by cluster bounds on the free completion's value
        # (completion_value.py) instead of trees along the free moves (FREE nodes, kept for the
        # authors' rule, whose observation mass is not linear in a hidden-state vector).
        # (not with the event graph's full mode: its junction rows along macro paths are not held)
        bounds_allowed = rule == "bayes" and (self.events is None or self.events.chains_only)
        # "auto": exact trees (L is then the policy's exact value) where they fit the node budget
        self.tree_leaves = completion_tree_leaves(tables, self.symbols, self.task, self.depth_cap)
        self.completion = bounds_allowed and (
            completion == "bounds" or (completion == "auto" and self.tree_leaves > AUTO_TREE_LEAVES))
        self.route = FreeRoute.build(tables, self.free_slot, self.next_p)
        self.touched = np.zeros((self.depth_cap + 2, tables.n_x, self.next_p.shape[0]), dtype=bool)
        self.completion_seconds = 0.0
        self.binding: list[int] = []
        self.completion_clusters = 0

    def move_table(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(target road, junctions, legal) [m, slots] and the free slot [m] of `nodes`' moves.

        Plain: the town's junctions (one junction each). Compressed: the event graph's macro moves;
        a legal slot with target -1 never reaches an event road (worth 0)."""
        g = self.graph
        if self.events is not None:
            return self.events.table(g.x[nodes], g.q[nodes], g.p[nodes])
        target = self.tables.successors[g.x[nodes]]
        legal = target >= 0
        return target, legal.astype(np.int64), legal, self.free_slot[g.x[nodes], g.q[nodes], g.p[nodes]]

    def level_arrays(self, level: int) -> ExpandedLevel:
        """The cached ExpandedLevel of `level`, rebuilt when nodes were expanded there."""
        g = self.graph
        members = g.expanded_by_level[level]
        cached = self.levels.get(level)
        if cached is not None and cached.count == len(members):
            return cached
        cached = self._level(np.array(members, dtype=np.int64), len(members))
        self.levels[level] = cached
        return cached

    def free_level_arrays(self, level: int) -> ExpandedLevel:
        """The FREE nodes of `level` as a ExpandedLevel whose only legal move is the free one."""
        g = self.graph
        version = g.free_version[level]
        cached = self.free_levels.get(level)
        if cached is not None and cached[0] == version:
            return cached[1]
        nodes = np.fromiter(g.free_by_level[level], dtype=np.int64)
        lv = self._level(nodes, nodes.size)
        only = np.zeros_like(lv.legal)
        only[np.arange(nodes.size), g.free_move[nodes]] = True
        lv = ExpandedLevel(**{**lv.__dict__, "legal": lv.legal & only})
        self.free_levels[level] = (version, lv)
        return lv

    def _level(self, nodes: np.ndarray, count: int) -> ExpandedLevel:
        g = self.graph
        child = g.child[nodes]
        return ExpandedLevel(count=count, nodes=nodes, child=np.maximum(child, 0), has_child=child >= 0,
                             prob=g.prob[nodes], legal=g.legal[nodes])

    @staticmethod
    def level_values3(lv: ExpandedLevel, values: np.ndarray) -> np.ndarray:
        """Move values Σ_o p(o) value(child) for U, L and the strict value at once, -1 where
        illegal: [3, nodes, moves] from values [3, n]."""
        child_value = np.where(lv.has_child[None], values[:, lv.child], 0.0)
        q = lv.prob[None, :, :, 0] * child_value[:, :, :, 0]
        for o in range(1, child_value.shape[3]):
            q += lv.prob[None, :, :, o] * child_value[:, :, :, o]
        return np.where(lv.legal[None], q, -1.0)

    def frontier_upper(self, level: int | np.ndarray, x: np.ndarray, q: np.ndarray, cell: np.ndarray
                       ) -> np.ndarray:
        return self.bound[np.minimum(level, self.bound.shape[0] - 1), x, q, cell]

    def classify(self, ids: np.ndarray) -> None:
        """Initialise new nodes: terminal values, or the frontier's abstract bound."""
        g, tables = self.graph, self.tables
        level = g.level[ids]
        q = g.q[ids]
        accepted = tables.accepting[q]
        g.kind[ids[accepted]] = ACCEPTED
        g.upper[ids[accepted]] = g.lower[ids[accepted]] = g.strict[ids[accepted]] = 1.0
        g.free_upper[ids[accepted]] = 1.0
        g.completed[ids[accepted]] = True
        rest = ids[~accepted]
        if rest.size == 0:
            return
        level = level[~accepted]
        upper = np.minimum(1.0, self.frontier_upper(level, g.x[rest], g.q[rest], g.cell[rest]))
        dead = tables.rejecting[g.q[rest]] | (upper <= 0.0)
        if self.horizon is not None:
            # graph distance: acceptance needs more junctions than are left -> exactly 0
            dead |= self.distance[g.x[rest], g.q[rest]] > self.horizon - level
        g.kind[rest[dead]] = ZERO
        g.upper[rest[dead]] = 0.0
        g.lower[rest[dead]] = 0.0
        g.strict[rest[dead]] = 0.0
        g.free_upper[rest[dead]] = 0.0
        g.completed[rest[dead]] = True
        live = rest[~dead]
        g.upper[live] = upper[~dead]
        g.free_upper[live] = upper[~dead]
        g.lower[live] = 0.0
        g.strict[live] = 0.0

    def next_q(self, q: np.ndarray, x2: np.ndarray, belief: np.ndarray, word: np.ndarray) -> np.ndarray:
        """DFA states after reading (x2, belief) from q, the belief the float image of the exact
        one after `word`: labels read as the vehicle and `evaluate` read them
        (exact_labels.ExactLabels)."""
        tables = self.tables
        if q.size == 0 or not tables.belief_atom_names:
            return tables.step(q, x2, belief)
        truth = self.labels.truth(belief, word)
        return np.asarray(tables.labeller.step(q, x2, belief, belief_truth=truth), dtype=np.int64)

    def roots(self) -> np.ndarray:
        """The root node (one, as an array: its labels decided exactly on the prior)."""
        tables = self.tables
        b0 = np.asarray(tables.pomdp.initial_belief, dtype=float)[None, :]
        x0 = np.array([tables.start])
        empty_word = np.zeros(1, dtype=np.int64)
        q0 = self.next_q(np.array([tables.dfa.initial]), x0, b0, empty_word)
        ids, _ = self.graph.add(0, x0, q0, np.full(1, self.task.initial_state, dtype=np.int64),
                                np.zeros(1, dtype=np.int64), b0, empty_word)
        self.classify(ids)
        return ids

    def expand(self, nodes: np.ndarray, free_only: bool = False) -> None:
        """Expand `nodes` (FRONTIER or FREE, any levels) along every move (EXPANDED), or along
        the trust-free completion's move only (free_only: FRONTIER -> FREE)."""
        g, tables, symbols = self.graph, self.tables, self.symbols
        nodes = np.asarray(nodes, dtype=np.int64)
        if nodes.size == 0:
            return
        x2_all, length_all, legal, free_move = self.move_table(nodes)        # [m, slots]
        g.legal[nodes] = legal
        g.free_move[nodes] = free_move
        valid = legal & (x2_all >= 0)
        if self.horizon is not None:
            # a move longer than the junctions left ends at the horizon: no child, worth 0
            valid &= g.level[nodes][:, None] + length_all <= self.horizon
        if free_only:
            valid &= np.arange(x2_all.shape[1])[None, :] == free_move[:, None]
        incident = tables.pomdp.road_incident[np.maximum(x2_all, 0)]
        symbol_all = self.symbols_of_incident[incident]                           # [m, actions, s]
        row, slot, j = np.nonzero(valid[:, :, None] & (symbol_all >= 0))
        parent, symbol, x2 = nodes[row], symbol_all[row, slot, j], x2_all[row, slot]
        length = length_all[row, slot]
        # The quiet roads before a macro move's target leave the belief as it is and have
        # probability exactly 1 (event_graph.py): only the target's observation counts.
        belief, probability = apply_symbol(g.belief[parent], symbols, symbol)
        keep = probability > 0
        parent, slot, symbol, x2, belief, probability, length = (
            a[keep] for a in (parent, slot, symbol, x2, belief, probability, length))
        level2 = g.level[parent] + length
        word = self.labels.filter.extend(g.word[parent], self.symbol_codes[symbol])
        q2 = self.next_q(g.q[parent], x2, belief, word)
        cell2 = self.cells.next_cell[g.cell[parent], symbol]
        p2 = self.next_p[g.p[parent], x2]
        ids, new = g.add(level2, x2, q2, p2, cell2, belief, word)
        outcome = self.slot_of_symbol[symbol]
        g.child[parent, slot, outcome] = ids
        g.prob[parent, slot, outcome] = probability
        self.classify(ids[new])
        levels = g.level[nodes]
        for level in np.unique(levels).tolist():
            members = nodes[levels == level].tolist()
            free_here = g.free_by_level[level]
            if free_only:
                free_here.update(dict.fromkeys(members))
            else:
                for n in members:
                    free_here.pop(n, None)
                g.expanded_by_level[level].extend(members)
            g.free_version[level] += 1
        g.kind[nodes] = FREE if free_only else EXPANDED
        spend(CHILD_UNITS * row.size)

    def backup(self) -> None:
        """Bellman backups from the deepest level up. At each level the FREE nodes first (L and the
        strict value are their one move's; U stays the abstraction's, the other moves being
        unexplored), then the EXPANDED ones (U: min(U, max over moves); L: max over moves).
        The move values and the policy's moves are kept (self.moves) for the reach computations
        until the next expansion."""
        g = self.graph
        spend(1 + g.n // NODES_PER_UNIT)
        self.moves = {}
        self.binding = []
        if self.completion:
            self.touched = free_touched(self.graph, self.route, self.touched.shape)
        # (else all False: nothing is valued by a completion bound)
        for level in range(len(g.expanded_by_level) - 1, -1, -1):
            moves = []
            if g.free_by_level[level]:
                lv = self.free_level_arrays(level)
                q3 = self.level_values3(lv, g.values)
                g.lower[lv.nodes] = np.maximum(g.lower[lv.nodes], q3[1].max(axis=1))
                g.strict[lv.nodes] = q3[2].max(axis=1)
                moves.append((lv, q3[0].argmax(axis=1), policy_choice(q3[1], q3[2], q3[0])))
            if g.expanded_by_level[level]:
                lv = self.level_arrays(level)
                nodes = lv.nodes
                q3 = self.level_values3(lv, g.values)
                g.upper[nodes] = np.minimum(g.upper[nodes], q3[0].max(axis=1))
                # L and the strict value of the policy's own move (assigned: the move may be held
                # to the free one, see choose)
                move, lower_q, strict_q = self.choose(nodes, q3[1], q3[2], q3[0])
                rows = np.arange(nodes.size)
                g.lower[nodes] = lower_q[rows, move]
                g.strict[nodes] = strict_q[rows, move]
                moves.append((lv, q3[0].argmax(axis=1), move))
            self.moves[level] = moves

    def choose(self, nodes: np.ndarray, lower_q: np.ndarray, strict_q: np.ndarray, upper_q: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The returned policy's move at EXPANDED `nodes`, with the move values it is judged by.

        The free move's L is raised to the node's completion bound (free_lower): the policy's
        value from the node along the free move is at least the free completion's, because of the
        rule below. Rule (the completion bounds are sound only with it): at a node that the free
        completion from a node valued by its completion bound can reach (`touched`), the policy
        leaves the free move only for a move whose L is at least the free completion's upper
        bound there. Then, by induction over the junctions left, the policy's value at every such
        node is at least the free completion's (docs/synthesis.md, "Open nodes and the acting
        rule"). Among the allowed moves: policy_choice (best L, ties by strict value, then U)."""
        g = self.graph
        free = g.free_move[nodes]           # the free slot among the node's moves
        held = self.touched[g.level[nodes], g.x[nodes], g.p[nodes]]
        move, lower_q, strict_q = held_choice(lower_q, strict_q, upper_q, free, held,
                                              g.free_lower[nodes], g.free_upper[nodes])
        if self.completion:
            # held rows whose completion bounds are not computed yet and where the rule changes the
            # move: bounding the free completion there may free the better move (refinement.py)
            binding = ~g.completed[nodes] & (move != policy_choice(lower_q, strict_q, upper_q))
            self.binding.extend(nodes[binding].tolist())
        return move, lower_q, strict_q

    def complete(self, nodes: np.ndarray, deadline: float) -> None:
        """Cluster bounds on the free completion's value from `nodes` (open_node_bounds.py), until
        the deadline."""
        started = time.perf_counter()
        clusters = bound_completions(self.graph, self.tables, self.symbols, self.route, nodes,
                                     self.depth_cap, deadline)
        self.completion_clusters = max(self.completion_clusters, clusters)
        self.completion_seconds += time.perf_counter() - started

    def greedy_children(self, nodes: np.ndarray, mass: np.ndarray, depth_cap: int
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Open (FRONTIER or FREE) children of EXPANDED `nodes` along their upper-greedy move by
        their children's current U, with the reach mass they get from `mass` (summed over
        parents), shallower than depth_cap and with a positive gap."""
        g = self.graph
        child = g.child[nodes]
        has = child >= 0
        child_upper = np.where(has, g.upper[np.maximum(child, 0)], 0.0)
        q_upper = (g.prob[nodes] * child_upper).sum(axis=2)
        q_upper = np.where(g.legal[nodes], q_upper, -1.0)
        move = q_upper.argmax(axis=1)
        rows = np.arange(nodes.size)
        kids, kid_prob, kid_has = child[rows, move], g.prob[nodes][rows, move], has[rows, move]
        kid_mass = mass[:, None] * kid_prob
        kids, kid_mass = kids[kid_has], kid_mass[kid_has]
        open_kid = (((g.kind[kids] == FRONTIER) | (g.kind[kids] == FREE)) & (g.level[kids] < depth_cap)
                    & (g.upper[kids] > g.lower[kids]))
        kids, kid_mass = kids[open_kid], kid_mass[open_kid]
        if kids.size == 0:
            return kids, kid_mass
        unique, inverse = np.unique(kids, return_inverse=True)
        return unique, np.bincount(inverse, weights=kid_mass, minlength=unique.size)

    def reach_lower(self, roots: np.ndarray, trust_free: bool = False) -> np.ndarray:
        """Probability of reaching each node under the returned policy (its move at EXPANDED
        nodes, the free move at FREE ones), from the moves of the last backup. trust_free: under
        the trust-free completion everywhere instead."""
        g = self.graph
        reach = np.zeros(g.n)
        reach[roots] = 1.0
        for level in sorted(self.moves):
            for lv, _, move in self.moves[level]:
                self._push(reach, lv, g.free_move[lv.nodes] if trust_free else move)
        return np.minimum(reach, 1.0)

    @staticmethod
    def _push(reach: np.ndarray, lv: ExpandedLevel, move: np.ndarray | None) -> None:
        """Add the reach mass of lv's nodes to their children along `move` (None: every move)."""
        mass_here = reach[lv.nodes]
        if not (mass_here > 0).any():
            return
        if move is None:
            chosen = lv.legal
        else:
            chosen = np.zeros(lv.legal.shape, dtype=bool)
            chosen[np.arange(lv.nodes.size), move] = True
            chosen &= lv.legal
        mass = mass_here[:, None, None] * lv.prob * (chosen[:, :, None] & lv.has_child)
        np.add.at(reach, lv.child[lv.has_child], mass[lv.has_child])

    def reach(self, roots: np.ndarray, every_action: bool = False) -> np.ndarray:
        """Probability of reaching each node under the upper-greedy policy. every_action: every
        action carries the node's full mass instead (used once the upper-greedy frontier is closed
        while the gap is not: the returned policy's move, held to the free one, may lead elsewhere).
        Only EXPANDED nodes pass mass on; from the moves of the last backup."""
        g = self.graph
        reach = np.zeros(g.n)
        reach[roots] = 1.0
        for level in sorted(self.moves):
            for lv, upper_move, _ in self.moves[level]:
                if lv is self.levels.get(level):
                    self._push(reach, lv, None if every_action else upper_move)
        return np.minimum(reach, 1.0)
