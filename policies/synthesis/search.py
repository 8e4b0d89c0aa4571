"""Policy synthesis with certified bounds: lower <= Pr_max(spec) <= upper (docs/model.md, "What L and U
mean").

Method (bounded heuristic search over the product belief MDP, with a sound abstraction at the frontier):

* The exact product belief MDP is unfolded from (start, initial belief, q_0) as an AND-OR graph:
  one node per distinct (junctions t, road x, DFA state q, state-only task state p, belief bytes) —
  identical beliefs at the same depth are merged, never approximated. A node's children are, per
  next junction, the observation symbols with their exact probabilities and exact Bayes (or
  "paper") posteriors.
* Every node carries [L, U]. FRONTIER (unexpanded) nodes: U = the suffix abstraction's bound at the
  node's cell (policies/synthesis/upper_bound.py; the cell is the node's last k belief-changing
  symbols, which it knows exactly); L = a lower bound of the trust-free completion's value from
  the node (Bayes rule: cluster bounds, policies/synthesis/completion_value.py; 0 until computed).
  FREE nodes (authors' rule only; expanded along the trust-free completion's move only): L = that
  move's value, U = the bound. Terminal nodes are exact: accepted
  1, rejected 0, horizon reached 0. EXPANDED nodes: U = min(U, max_a Σ_o p U_child) and
  L = max_a Σ_o p L_child.
* Refinement (AO*/HSVI style): per round, expand the open nodes carrying the most of the root's
  gap — reach probability under the upper-greedy policy times (U - L) — and look ahead along their
  upper-greedy moves; bound (Bayes) or free-expand (authors' rule) the FRONTIER nodes the
  returned policy reaches; until U - L <= tau at the root, the frontier is exhausted, or the time
  limit.
* The returned policy takes at every EXPANDED node the action maximising L among those the hold
  rule allows (ties: strict value, then U) and drives the free completion everywhere else
  (the exact-belief acting rule of policies.routing.aware_table.BeliefTablePolicy): the trust-free
  completion of the state-only task, then the shortest route back to what the DFA still needs,
  every label allowed (policies/routing/free.py, `free_completion`; "the trust-free completion"
  below). After the
  last round the completions it reaches are bounded (Bayes) or closed (authors' rule), so `lower`
  is a lower bound of that policy's value (its exact value under the authors' rule). Where a
  completion bound is used, rows its route can reach may leave the free move only for a move
  worth at least the completion's upper bound (the hold rule, `_Search.choose`), which keeps the
  bound sound (docs/synthesis.md, "Open nodes and the acting rule").

Horizon H: at most H junctions (the study measures "policy, then fallback after 20", so H = 20 is
the natural companion). Unbounded (horizon=None): upper is the abstraction's least fixed point with
end components collapsed (policies/synthesis/end_components.py), tightened by a search of the
unbounded problem itself (open nodes, including those deeper than UNBOUNDED_DEPTH, valued by that
bound); lower is the best of that search and bounded searches with growing H (their policies are
policies for the unbounded problem too, worth at least their bounded value).

Cluster policies (Bayes rule; policies/synthesis/cluster_policy.py, docs/synthesis.md "Cluster
policies"): the whole product solved with beliefs enclosed in boxes, a policy of box rows with its
own certified [L, U]. `synthesize` runs them before the search on large problems and after an
unconverged search elsewhere (CLUSTER_MODES), and returns the better L with its policy and the
smaller U.

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

from trustroute.policies.belief.product_mdp import ProductTables, build_product
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.routing.aware_table import BeliefTablePolicy, PolicyTable
from trustroute.policies.routing.free import StateOnlyTask, free_completion, state_only_task
from trustroute.policies.synthesis.arguments import check_synthesis_arguments
from trustroute.policies.synthesis.belief_cells import (
    ObservationSymbols,
    apply_symbol,
    observation_symbols,
    suffix_cells,
)
from trustroute.policies.synthesis.cluster_policy import ClusterSolution, best_cluster_solution
from trustroute.policies.synthesis.completion_value import FreeRoute, completion_bounds
from trustroute.policies.synthesis.end_components import unbounded_bound
from trustroute.policies.synthesis.event_graph import EventGraph
from trustroute.policies.synthesis.upper_bound import (
    Abstraction,
    acceptance_distance,
    bounded_upper,
    build_abstraction,
)

CELL_BUDGET = 5000          # automatic suffix length: the longest k with n_symbols**k <= this
DEFAULT_BATCH = 4096
MIN_BATCH = 64
NODE_BUDGET = 600_000   # search nodes (about 0.7 kB each with the memo): the search stops there
LOOKAHEAD = 3      # further expansion steps per round along the upper-greedy moves
FULL_SHARE = 0.5   # share of the gap-weighted frontier fully expanded per round
FREE_SHARE = 1.0   # share of the policy's open mass free-expanded per round (1: all of it)
UNBOUNDED_HORIZONS = (20, 30, 40, 60, 80, 120, 160)
UNBOUNDED_DEPTH = 60        # the unbounded search leaves nodes this deep open (<= evaluate's cap)
UNBOUNDED_STATE_BUDGET = 20_000
UNBOUNDED_BOUND_SHARE = 0.3  # share of the time limit the end-component bound may take
BOUNDED_ENTRY_BUDGET = 20_000_000   # floats of the bounded abstraction (160 MB)
FINISH_SHARE = 0.04          # share of the time limit kept for finishing after the last check
COMPLETION_CHUNK = 64        # start nodes per batched cluster propagation (memory: ~25 MB each)
COMPLETION_TAIL = 0.05       # open nodes left unbounded (L = 0) carry at most this share of tau
# Most macro moves per context for which the event graph is used: node arrays hold one slot per
# move, so a town whose quiet roads connect many event roads is searched junction by junction.
MAX_MACRO_WIDTH = 16
# How open nodes are valued: "exact" trees along the free moves (L is the returned policy's exact
# value; the trees grow exponentially with the incident roads left on long routes), "bounds"
# (cluster bounds on the completion, completion_value.py; L a lower bound of the policy's value),
# "auto": exact where the trust-free route's own observation tree within the horizon has at most
# AUTO_TREE_LEAVES leaves (completion_tree_leaves), bounds otherwise.
COMPLETION_MODES = ("auto", "exact", "bounds")
AUTO_TREE_LEAVES = NODE_BUDGET // 4
COMPRESS_MODES = ("off", "chains", "full")
# Cluster policies (cluster_policy.py) under the Bayes rule: "auto" before the search where open
# nodes would get cluster bounds (the free route's observation tree exceeds AUTO_TREE_LEAVES), and
# after it elsewhere when the search ends with a gap above tau (it then has SEARCH_SHARE of the
# time); "on" always before the search; "off" never.
CLUSTER_MODES = ("auto", "on", "off")
CLUSTER_SHARE = 0.75          # share of the time limit the cluster policies may take before the search
SEARCH_SHARE = 0.5            # share of the time limit of a search that cluster policies may follow
# unbounded: cluster policies for these junction counts beyond the shortest acceptance, in turn
UNBOUNDED_CLUSTER_SLACK = (10, 20, 30, 45)
UNBOUNDED_CLUSTER_CAPS = (16, 64, 256)

# FRONTIER: open, L = 0 (the policy drives the trust-free completion there, worth >= 0).
# FREE: expanded along the trust-free completion's move only; L is that move's exact value, U the
# abstraction's bound (the other moves are unexplored). EXPANDED: every move; a policy row.
FRONTIER, EXPANDED, ACCEPTED, ZERO, FREE = 0, 1, 2, 3, 4


@dataclass(frozen=True, eq=False)
class SynthesisResult:
    """lower <= Pr_max <= upper; lower is a certified lower bound of the value of `policy`.

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
        self.p = np.zeros(capacity, dtype=np.int64)      # state of the state-only task (free route)
        self.cell = np.zeros(capacity, dtype=np.int64)
        self.belief = np.zeros((capacity, n_trust))
        # U, L and the strict value as rows of one array, so that a backup gathers all three at once
        self.values = np.zeros((3, capacity))
        self.upper, self.lower = self.values[0], self.values[1]
        # value of the L-greedy choice with every label read strictly, as this machine's labeller
        # does (no alternates): the tie-breaker among actions of equal L, and a reported figure.
        self.strict = self.values[2]
        self.kind = np.zeros(capacity, dtype=np.int8)
        # Bounds on the trust-free completion's value from the node (completion_value.py): its
        # lower bound is the L of a FRONTIER node; its upper bound decides where the policy may
        # leave the free move (_Search.choose). free_upper starts at the abstraction's bound.
        self.free_upper = np.zeros(capacity)
        self.free_lower = np.zeros(capacity)
        self.completed = np.zeros(capacity, dtype=bool)
        # per expanded node: which move slots exist, and the trust-free completion's slot
        self.legal = np.zeros((capacity, n_actions), dtype=bool)
        self.free_move = np.zeros(capacity, dtype=np.int64)
        self.child = np.full((capacity, n_actions, n_outcomes), -1, dtype=np.int64)
        self.prob = np.zeros((capacity, n_actions, n_outcomes))
        self.memo: list[dict[tuple[int, int, int, bytes], int]] = []
        self.expanded_by_level: list[list[int]] = []
        self.free_by_level: list[dict[int, None]] = []    # FREE nodes per level (insertion order)
        self.free_version: list[int] = []
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
        for name in ("level", "x", "q", "p", "cell", "kind", "free_move", "free_upper", "free_lower",
                     "completed"):
            old = getattr(self, name)
            grown = np.zeros(new, dtype=old.dtype)
            grown[:capacity] = old
            setattr(self, name, grown)
        values = np.zeros((3, new))
        values[:, :capacity] = self.values
        self.values = values
        self.upper, self.lower, self.strict = values[0], values[1], values[2]
        belief = np.zeros((new, self.belief.shape[1]))
        belief[:capacity] = self.belief
        self.belief = belief
        child = np.full((new, self.n_actions, self.n_outcomes), -1, dtype=np.int64)
        child[:capacity] = self.child
        self.child = child
        legal = np.zeros((new, self.n_actions), dtype=bool)
        legal[:capacity] = self.legal
        self.legal = legal
        prob = np.zeros((new, self.n_actions, self.n_outcomes))
        prob[:capacity] = self.prob
        self.prob = prob

    def add(self, level: int | np.ndarray, x: np.ndarray, q: np.ndarray, p: np.ndarray,
            cell: np.ndarray, belief: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ids of the nodes (level, x, q, p, belief), creating missing ones; and a mask of new ones."""
        level = np.broadcast_to(np.asarray(level, dtype=np.int64), x.shape)
        deepest = int(level.max()) if level.size else 0
        while len(self.memo) <= deepest:
            self.memo.append({})
            self.expanded_by_level.append([])
            self.free_by_level.append({})
            self.free_version.append(0)
        memos = self.memo
        ids = np.empty(x.size, dtype=np.int64)
        new = np.zeros(x.size, dtype=bool)
        start = self.n
        self._grow(self.n + x.size)
        for i, (lv, *key) in enumerate(zip(level.tolist(), x.tolist(), q.tolist(), p.tolist(),
                                           (row.tobytes() for row in belief), strict=True)):
            memo = memos[lv]
            node = memo.get(tuple(key))
            if node is None:
                node = self.n
                memo[tuple(key)] = node
                self.n += 1
                new[i] = True
            ids[i] = node
        created = ids[new]
        self.level[created] = level[new]
        self.x[created] = x[new]
        self.q[created] = q[new]
        self.p[created] = p[new]
        self.cell[created] = cell[new]
        self.belief[created] = belief[new]
        self.kind[created] = FRONTIER
        self.completed[created] = False
        self.free_lower[created] = 0.0
        assert self.n == start + created.size
        return ids, new


@dataclass(frozen=True, eq=False)
class _Level:
    """The expanded nodes of one level with their (fixed) children, for the backups.

    nodes [m]; child [m, actions, outcomes] (0 where absent, masked by has_child); prob; legal
    [m, actions]; alternates as (row, slot, outcome, child) with row an index into nodes."""

    count: int
    alternate_chunks: int
    nodes: np.ndarray
    child: np.ndarray
    has_child: np.ndarray
    prob: np.ndarray
    legal: np.ndarray
    alt_row: np.ndarray
    alt_slot: np.ndarray
    alt_outcome: np.ndarray
    alt_child: np.ndarray


class _Search:
    def __init__(self, tables: ProductTables, rule: BeliefRule, horizon: int | None, suffix_length: int,
                 started: float, deadline: float, unbounded_value: np.ndarray | None = None,
                 abstraction: Abstraction | None = None, compress: str = "chains",
                 completion: str = "auto") -> None:
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
            self.bound = np.asarray(unbounded_value)[None]
            self.bound_note = ("the unbounded abstraction's least fixed point from above, end "
                               "components collapsed (policies/synthesis/end_components.py)")
        self.abstraction_seconds = time.perf_counter() - started
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
        self.row_conflicts = 0
        if compress not in COMPRESS_MODES:
            raise ValueError(f"unknown compression {compress!r}; use one of {', '.join(COMPRESS_MODES)}")
        if compress != "off":
            events = EventGraph(tables, self.symbols, self.task, chains_only=compress == "chains",
                                free_slot=self.free_slot)
            if events.compresses and events.width <= MAX_MACRO_WIDTH:
                self.events = events
            self.macro_width = events.width
        n_actions = self.events.width if self.events is not None else tables.successors.shape[1]
        self.graph = _Graph(pomdp.n_trust, n_actions, n_outcomes)
        self.levels: dict[int, _Level] = {}
        self.moves: dict[int, list[tuple[_Level, np.ndarray, np.ndarray]]] = {}
        self.free_levels: dict[int, tuple[int, _Level]] = {}
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

    def level_arrays(self, level: int) -> _Level:
        """The cached _Level of `level`, rebuilt when nodes or alternates were added there."""
        g = self.graph
        members = g.expanded_by_level[level]
        chunks = len(g.alternates.get(level, ()))
        cached = self.levels.get(level)
        if cached is not None and cached.count == len(members) and cached.alternate_chunks == chunks:
            return cached
        cached = self._level(level, np.array(members, dtype=np.int64), chunks, len(members))
        self.levels[level] = cached
        return cached

    def free_level_arrays(self, level: int) -> _Level:
        """The FREE nodes of `level` as a _Level whose only legal move is the free one."""
        g = self.graph
        version = (g.free_version[level], len(g.alternates.get(level, ())))
        cached = self.free_levels.get(level)
        if cached is not None and cached[0] == version:
            return cached[1]
        nodes = np.fromiter(g.free_by_level[level], dtype=np.int64)
        lv = self._level(level, nodes, version[1], nodes.size)
        only = np.zeros_like(lv.legal)
        only[np.arange(nodes.size), g.free_move[nodes]] = True
        lv = _Level(**{**lv.__dict__, "legal": lv.legal & only})
        self.free_levels[level] = (version, lv)
        return lv

    def _level(self, level: int, nodes: np.ndarray, chunks: int, count: int) -> _Level:
        g = self.graph
        child = g.child[nodes]
        parent, slot, outcome, alt_child = g.alternates_of(level)
        row = np.zeros(0, dtype=np.int64)
        if parent.size:
            order = np.argsort(nodes, kind="stable")
            where = np.minimum(np.searchsorted(nodes[order], parent), nodes.size - 1)
            hit = nodes[order][where] == parent
            row, slot, outcome, alt_child = order[where[hit]], slot[hit], outcome[hit], alt_child[hit]
        else:
            slot = outcome = alt_child = row
        return _Level(count=count, alternate_chunks=chunks, nodes=nodes,
                      child=np.maximum(child, 0), has_child=child >= 0, prob=g.prob[nodes],
                      legal=g.legal[nodes], alt_row=row, alt_slot=slot,
                      alt_outcome=outcome, alt_child=alt_child)

    @staticmethod
    def level_values3(lv: _Level, values: np.ndarray) -> np.ndarray:
        """level_values for U (optimistic), L (pessimistic) and the strict value at once:
        [3, nodes, moves] from values [3, n]."""
        child_value = np.where(lv.has_child[None], values[:, lv.child], 0.0)
        if lv.alt_row.size:
            index = (lv.alt_row, lv.alt_slot, lv.alt_outcome)
            np.maximum.at(child_value[0], index, values[0, lv.alt_child])
            np.minimum.at(child_value[1], index, values[1, lv.alt_child])
        q = lv.prob[None, :, :, 0] * child_value[:, :, :, 0]
        for o in range(1, child_value.shape[3]):
            q += lv.prob[None, :, :, o] * child_value[:, :, :, o]
        return np.where(lv.legal[None], q, -1.0)

    @staticmethod
    def level_values(lv: _Level, values: np.ndarray, pessimistic: bool | None) -> np.ndarray:
        """Move values on a cached level: Σ_o p(o) value(child) per action, -1 where illegal."""
        child_value = np.where(lv.has_child, values[lv.child], 0.0)
        if pessimistic is not None and lv.alt_row.size:
            combine = np.minimum.at if pessimistic else np.maximum.at
            combine(child_value, (lv.alt_row, lv.alt_slot, lv.alt_outcome), values[lv.alt_child])
        q = lv.prob[:, :, 0] * child_value[:, :, 0]
        for o in range(1, child_value.shape[2]):
            q += lv.prob[:, :, o] * child_value[:, :, o]
        return np.where(lv.legal, q, -1.0)

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
        ids, _ = self.graph.add(0, np.repeat(x0, qs.size), qs,
                                np.full(qs.size, self.task.initial_state, dtype=np.int64),
                                np.zeros(qs.size, dtype=np.int64), np.repeat(b0, qs.size, axis=0))
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
        q2, alt_rows, alt_q = self.possible_q(g.q[parent], x2, belief)
        cell2 = self.cells.next_cell[g.cell[parent], symbol]
        p2 = self.next_p[g.p[parent], x2]
        ids, new = g.add(level2, x2, q2, p2, cell2, belief)
        outcome = self.slot_of_symbol[symbol]
        g.child[parent, slot, outcome] = ids
        g.prob[parent, slot, outcome] = probability
        self.classify(ids[new])
        if alt_rows.size:
            alt_ids, alt_new = g.add(level2[alt_rows], x2[alt_rows], alt_q, p2[alt_rows],
                                     cell2[alt_rows], belief[alt_rows])
            self.classify(alt_ids[alt_new])
            alt_level = g.level[parent[alt_rows]]
            for level in np.unique(alt_level).tolist():
                here = alt_rows[alt_level == level]
                g.add_alternates(level, parent[here], slot[here], outcome[here],
                                 alt_ids[alt_level == level])
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

    def backup(self) -> None:
        """Bellman backups from the deepest level up. At each level the FREE nodes first (L and the
        strict value are their one move's; U stays the abstraction's, the other moves being
        unexplored), then the EXPANDED ones (U: min(U, max over moves); L: max over moves).
        The move values and the policy's moves are kept (self.moves) for the reach computations
        until the next expansion."""
        g = self.graph
        self.moves = {}
        self.binding = []
        self.touched = self.free_touched()
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
            # move: bounding the free completion there may free the better move (search loop)
            binding = ~g.completed[nodes] & (move != policy_choice(lower_q, strict_q, upper_q))
            self.binding.extend(nodes[binding].tolist())
        return move, lower_q, strict_q

    def free_touched(self) -> np.ndarray:
        """bool [level, x, p]: keys the free completion can reach, one junction or more after a
        node whose L uses its completion bound (free_lower > 0); belief and DFA state ignored
        (a superset)."""
        if not self.completion:
            return self.touched          # all False: nothing is valued by a completion bound
        g = self.graph
        touched = np.zeros_like(self.touched)
        source = np.flatnonzero(g.completed[: g.n] & (g.free_lower[: g.n] > 0))
        start = np.zeros_like(touched)
        start[g.level[source], g.x[source], g.p[source]] = True
        road, task = self.route.next_road, self.route.next_task
        carried = np.zeros(touched.shape[1:], dtype=bool)
        for level in range(touched.shape[0] - 1):
            carried = carried | start[level]
            nxt = np.zeros_like(carried)
            xs, ps = np.nonzero(carried)
            nxt[road[xs, :, ps].ravel(), task[xs, :, ps].ravel()] = True     # every DFA state
            touched[level + 1] = nxt
            carried = nxt
        return touched

    def complete(self, nodes: np.ndarray, deadline: float) -> None:
        """Cluster bounds on the free completion's value from `nodes` (completion_value.py):
        free_lower (a FRONTIER node's L and strict value) and free_upper. Stops at the deadline."""
        g = self.graph
        nodes = nodes[~g.completed[nodes]]
        started = time.perf_counter()
        for begin in range(0, nodes.size, COMPLETION_CHUNK):
            if time.perf_counter() >= deadline:
                break
            chunk = nodes[begin:begin + COMPLETION_CHUNK]
            bounds = completion_bounds(self.tables, self.symbols, self.route, g.x[chunk], g.q[chunk],
                                       g.p[chunk], g.belief[chunk], self.depth_cap - g.level[chunk],
                                       deadline)
            # (stopped by the deadline, the chunk's bounds are sound but loose; they are kept, as
            # the node is marked completed, since nothing runs after the deadline to redo them)
            g.free_lower[chunk] = bounds.lower
            g.free_upper[chunk] = np.minimum(g.free_upper[chunk], bounds.upper)
            g.completed[chunk] = True
            frontier = chunk[g.kind[chunk] == FRONTIER]
            g.lower[frontier] = np.maximum(g.lower[frontier], g.free_lower[frontier])
            g.strict[frontier] = np.maximum(g.strict[frontier], g.free_lower[frontier])
            self.completion_clusters = max(self.completion_clusters, bounds.clusters)
        self.completion_seconds += time.perf_counter() - started

    def close_completions(self, roots: np.ndarray, depth_cap: int, deadline: float) -> bool:
        """Free-expand FRONTIER nodes reached by the returned policy, or by the trust-free route
        from the root, until there are none (True) or the deadline or NODE_BUDGET comes first
        (False: L is then a lower bound of the policy's value). Then L is the
        policy's exact value (every node it reaches without a row is valued by the completion it
        drives there), and L at the root is at least the trust-free route's value (along that
        route's tree every node is closed, and an EXPANDED node's L is at least its free move's)."""
        g = self.graph
        while True:
            reach = self.reach_lower(roots) + self.reach_lower(roots, trust_free=True)
            todo = np.flatnonzero((g.kind[: g.n] == FRONTIER) & (g.level[: g.n] < depth_cap)
                                  & (reach > 0))
            if todo.size == 0:
                return True
            # Down the free moves without backups in between (the policy's move at a FREE node is
            # the free one whatever the values); then one backup, after which the policy's moves
            # at EXPANDED nodes may have changed, so reach is computed again.
            while todo.size:
                if time.perf_counter() >= deadline or g.n >= NODE_BUDGET:
                    self.backup()
                    return False
                self.expand(todo, free_only=True)
                kids = g.child[todo].ravel()
                kids = np.unique(kids[kids >= 0])
                todo = kids[(g.kind[kids] == FRONTIER) & (g.level[kids] < depth_cap)]
            self.backup()

    def close_bounds(self, roots: np.ndarray, depth_cap: int, deadline: float, tail: float) -> bool:
        """Give the FRONTIER nodes the returned policy reaches their completion bounds, heaviest
        first, until those left carry at most `tail` of reach times U (True) or the deadline
        comes (False). Nodes left keep L = 0, which is sound."""
        g = self.graph
        while True:
            reach = self.reach_lower(roots)
            todo = np.flatnonzero((g.kind[: g.n] == FRONTIER) & ~g.completed[: g.n]
                                  & (g.level[: g.n] < depth_cap) & (reach > 0))
            todo = _heaviest_prefix(todo, reach[todo] * g.upper[todo], tail)
            todo = np.concatenate([todo, np.array(self.binding, dtype=np.int64)])
            if todo.size == 0:
                return True
            if time.perf_counter() >= deadline:
                return False
            self.complete(todo, deadline)
            self.backup()

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
        nodes, the free move at FREE ones; alternates each get their full probability), from the
        moves of the last backup. trust_free: under the trust-free completion everywhere instead."""
        g = self.graph
        reach = np.zeros(g.n)
        reach[roots] = 1.0
        for level in sorted(self.moves):
            for lv, _, move in self.moves[level]:
                self._push(reach, lv, g.free_move[lv.nodes] if trust_free else move)
        return np.minimum(reach, 1.0)

    @staticmethod
    def _push(reach: np.ndarray, lv: _Level, move: np.ndarray | None) -> None:
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
        if lv.alt_row.size:
            np.add.at(reach, lv.alt_child, mass[lv.alt_row, lv.alt_slot, lv.alt_outcome])

    def reach(self, roots: np.ndarray, every_action: bool = False) -> np.ndarray:
        """Probability of reaching each node under the upper-greedy policy (alternates of an
        outcome each get its full probability: either may be the one that happens). every_action:
        every action carries the node's full mass instead (used once the upper-greedy frontier is
        closed while the gap is not, as at thresholds where L takes the worse alternate). Only
        EXPANDED nodes pass mass on; from the moves of the last backup."""
        g = self.graph
        reach = np.zeros(g.n)
        reach[roots] = 1.0
        for level in sorted(self.moves):
            for lv, upper_move, _ in self.moves[level]:
                if lv is self.levels.get(level):
                    self._push(reach, lv, None if every_action else upper_move)
        return np.minimum(reach, 1.0)

    def policy_table(self) -> PolicyTable:
        """The EXPANDED nodes' moves as the last backup chose them (the moves L was computed
        with: recomputing the move values could differ in the last bit and flip a tie or the hold
        rule's comparison)."""
        g = self.graph
        parts = [(lv.nodes, move) for level in sorted(self.moves) for lv, _, move in self.moves[level]
                 if lv is self.levels.get(level)]
        nodes = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, dtype=np.int64)
        action = np.concatenate([p[1] for p in parts]) if parts else np.zeros(0, dtype=np.int64)
        assert nodes.size == int((g.kind[: g.n] == EXPANDED).sum())
        if self.events is not None and not self.events.chains_only:
            return self.junction_table(nodes, action, g.lower[nodes])
        # plain, or chains: a move is a junction slot, and the roads down a chain have one
        # junction each (no row needed), so the rows are the expanded nodes' own
        return PolicyTable(t=g.level[nodes], x=g.x[nodes], q=g.q[nodes], beliefs=g.belief[nodes],
                           action=action, projected=g.p[nodes])

    def junction_table(self, nodes: np.ndarray, action: np.ndarray, value: np.ndarray) -> PolicyTable:
        """The policy's rows junction by junction from its macro moves (docs/synthesis.md, "The
        event graph"): a row per road of the chosen move's path, at the junction count the vehicle
        is there, with the node's q, p and belief (none of them moves on quiet roads).

        Paths of different nodes can cross at the same context (t, road, q, p, belief); a context
        then takes the candidate with the largest L (a node's own row, then passing paths, then the
        trust-free completion of a FREE node passing there). Every candidate's L is a lower bound
        of following it, so the policy is worth at least L (stats "row_conflicts": how often)."""
        g, events = self.graph, self.events
        best: dict[tuple, tuple[float, int, int]] = {}     # context -> (L, -rank, slot) of the winner
        slots: dict[tuple, set[int]] = {}                  # context -> slots its candidates take
        has_row: set[tuple] = set()                        # contexts a policy row passes
        single = (self.tables.successors >= 0).sum(axis=1) == 1

        def offer(node: int, route: tuple, candidate_value: float, rank: int) -> None:
            t0, q, p = int(g.level[node]), int(g.q[node]), int(g.p[node])
            belief = g.belief[node].tobytes()
            for i, (road, slot) in enumerate(route):
                if self.horizon is not None and t0 + i >= self.horizon:
                    break
                if single[road]:        # one junction: no choice, no row needed
                    continue
                key = (t0 + i, road, q, p, belief)
                here = rank if rank == 2 or i == 0 else 1
                score = (candidate_value, -here, slot)
                slots.setdefault(key, set()).add(slot)
                if here < 2:
                    has_row.add(key)
                if key not in best or score[:2] > best[key][:2]:
                    best[key] = score

        for node, a, v in zip(nodes.tolist(), action.tolist(), value.tolist(), strict=True):
            moves = events.moves(int(g.x[node]), int(g.q[node]), int(g.p[node]))
            offer(node, moves.path[a], v, 0)
        for node in np.flatnonzero(g.kind[: g.n] == FREE).tolist():
            moves = events.moves(int(g.x[node]), int(g.q[node]), int(g.p[node]))
            offer(node, moves.path[moves.free], float(g.lower[node]), 2)
        self.row_conflicts = sum(1 for taken in slots.values() if len(taken) > 1)
        # A context only free completions pass needs no row (the policy drives them there anyway;
        # they all take the free completion's slot of (road, q, p)).
        keys = [key for key in best if key in has_row]
        beliefs = (np.array([np.frombuffer(key[4], dtype=float) for key in keys]) if keys
                   else np.zeros((0, g.belief.shape[1])))
        out_t, out_x, out_q, out_p = ([key[j] for key in keys] for j in range(4))
        out_a = [best[key][2] for key in keys]
        return PolicyTable(t=out_t, x=out_x, q=out_q, beliefs=beliefs, action=out_a, projected=out_p)


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
    """The hold rule (_Search.choose) on move values [nodes, moves]: (move, lower_q, strict_q) with
    the free move's values raised to free_lower; a `held` node leaves its `free` move only for a move
    whose L is at least free_upper; among the allowed moves, policy_choice."""
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
                    on_iteration: Callable[[float, float], None] | None = None, compress: str = "chains",
                    completion: str = "auto") -> tuple[float, float, PolicyTable, dict]:
    """One AO*-style search; returns (lower, upper, table, stats).

    horizon H: P(accepted within H junctions). None: the unbounded problem, nodes deeper than
    UNBOUNDED_DEPTH left open with the unbounded abstraction's bound `unbounded_value`.
    """
    search = _Search(tables, belief_rule, horizon, suffix_length, started, deadline, unbounded_value,
                     abstraction, compress, completion)
    g = search.graph
    roots = search.roots()

    def root_bounds() -> tuple[float, float]:
        return float(g.lower[roots].min()), float(g.upper[roots].max())

    depth_cap = horizon if horizon is not None else UNBOUNDED_DEPTH
    iterations = 0
    expanded = 0
    while (np.subtract(*root_bounds()[::-1]) > tau and time.perf_counter() < deadline
           and g.n < NODE_BUDGET):
        # Full expansion: open nodes (FRONTIER or FREE) carrying most of the root's gap under the
        # upper-greedy policy.
        reach = search.reach(roots)
        reach_policy = search.reach_lower(roots)
        shallow = g.level[: g.n] < depth_cap
        frontier = np.flatnonzero(((g.kind[: g.n] == FRONTIER) | (g.kind[: g.n] == FREE)) & shallow)
        weight = reach[frontier] * (g.upper[frontier] - g.lower[frontier])
        if not (weight > 0).any():
            weight = search.reach(roots, every_action=True)[frontier] * (
                g.upper[frontier] - g.lower[frontier])
        positive = weight > 0
        frontier, weight = frontier[positive], weight[positive]
        if frontier.size == 0:
            break
        chosen = _heaviest(frontier, weight, batch, FULL_SHARE)
        search.expand(chosen)
        expanded += chosen.size
        # Look ahead: the new children the upper-greedy move of the just-expanded nodes reaches,
        # heaviest first, without a full backup in between (fewer rounds on deep optimal policies).
        chosen_reach = reach[chosen]
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
        # Free expansion: FRONTIER nodes the returned policy reaches (it drives the trust-free
        # completion there) with the most probability times what they could still be worth.
        known = reach_policy.size            # nodes that existed before this round's expansion
        open_nodes = np.flatnonzero((g.kind[:known] == FRONTIER) & (g.level[:known] < depth_cap))
        free_weight = reach_policy[open_nodes] * g.upper[open_nodes]
        positive = free_weight > 0
        if search.completion:
            # value them by the cluster bounds on the free completion, heaviest first, leaving a
            # light tail at L = 0
            search.complete(_heaviest_prefix(open_nodes[positive], free_weight[positive],
                                             COMPLETION_TAIL * tau), deadline)
        elif positive.any() and g.n < NODE_BUDGET:
            if FREE_SHARE >= 1.0:
                search.expand(open_nodes[positive], free_only=True)
            else:
                search.expand(_heaviest(open_nodes[positive], free_weight[positive], batch, FREE_SHARE),
                              free_only=True)
        search.backup()
        if search.binding:
            search.complete(np.array(search.binding, dtype=np.int64), deadline)
            search.backup()
        iterations += 1
        if on_iteration is not None:
            on_iteration(*root_bounds())
    search.backup()
    # Close the returned policy's trust-free completions: every open node it reaches is bounded
    # (completion bounds; up to a light tail) or expanded along the free move (exact completion:
    # then L is the policy's exact value). Unless the deadline comes first; L is a lower bound of
    # the policy's value either way. stats["completion_closed"] says which.
    closed = (search.close_bounds(roots, depth_cap, deadline, COMPLETION_TAIL * tau) if search.completion
              else search.close_completions(roots, depth_cap, deadline))
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
        "completion_closed": closed,
        # open nodes valued by cluster bounds (then L is a lower bound of the policy's value) or
        # by exact trees (then, closed, L is its exact value)
        "completion_bounds": bool(search.completion),
        "free_tree_leaves": search.tree_leaves,
        "completion_seconds": search.completion_seconds,
        "completion_clusters": search.completion_clusters,
        # the event graph's macro moves (None: not asked for), their widest context, and contexts
        # where the paths of two rows crossed (then L is a lower bound of the policy's value)
        "compressed": None if search.macro_width is None else search.events is not None,
        "macro_width": search.macro_width,
        "row_conflicts": search.row_conflicts,
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


def _cluster_order(tables: ProductTables, symbols: ObservationSymbols, horizon: int | None,
                   completion: str, clusters: str) -> str:
    """CLUSTER_MODES: "first" (cluster policies before the search), "after" (after a search that
    ends with a gap above tau) or "never"."""
    if clusters == "off" or symbols.rule != "bayes":
        return "never"
    if clusters == "on":
        return "first"
    depth = horizon if horizon is not None else UNBOUNDED_DEPTH
    large = completion == "auto" and completion_tree_leaves(
        tables, symbols, state_only_task(tables.pomdp.town, tables.spec), depth) > AUTO_TREE_LEAVES
    return "first" if large else "after"


def _cluster_table(solution: ClusterSolution, n_trust: int) -> PolicyTable:
    """A policy table of box rows only (the exact-belief rule then reads the boxes)."""
    return PolicyTable(t=[], x=[], q=[], beliefs=np.zeros((0, n_trust)), action=[], projected=[],
                       boxes=solution.rows)


def _cluster_run(solution: ClusterSolution, upper: float, horizon: int, tried: list) -> dict:
    """The stats line of a cluster policy (keys shared with the search's runs)."""
    return {"horizon": horizon, "method": "cluster policy", "lower": solution.lower, "upper": upper,
            "nodes": 0, "cluster_cap": solution.cap, "clusters": solution.clusters,
            "policy_rows": solution.rows.rows, "cluster_runs": tried, "threshold_alternates": 0,
            # labels read the worse way wherever a box straddles, so L holds under any reading
            "lower_strict_labels": solution.lower, "completion_closed": True,
            "completion_bounds": False}


def synthesize(pomdp: TrustPOMDP, spec: Spec, tau: float = 1e-3, time_limit: float = 60.0,
               horizon: int | None = None, belief_rule: BeliefRule = "bayes",
               suffix_length: int | None = None,
               batch: int = DEFAULT_BATCH,
               on_iteration: Callable[[float, float], None] | None = None,
               compress: str = "chains", completion: str = "auto", clusters: str = "auto"
               ) -> SynthesisResult:
    """Maximal probability of satisfying `spec` from (spec.start, initial belief), with a policy.

    horizon: at most this many junctions (None: unbounded). belief_rule: the AV's filter and the
    belief MDP's dynamics ("bayes", or the authors' "paper" update with observation probabilities
    b·P(o|θ) of that belief). Returns lower <= Pr_max <= upper with lower a lower bound of the value of
    the returned policy; stops when upper - lower <= tau or after about time_limit seconds.

    Unbounded: lower is the best P(accepted within H junctions) of bounded searches with growing H
    (UNBOUNDED_HORIZONS): a policy accepting within H with probability L satisfies the unbounded spec
    with probability >= L. upper is the unbounded abstraction's bound, tightened by a search of the
    unbounded problem when a gap remains. on_iteration(lower, upper): called after every expansion
    round with the current search's root bounds (progress bars). compress: "chains" passes through
    quiet roads without a choice, "full" searches the event graph's macro moves
    (policies/synthesis/event_graph.py), "off" goes junction by junction; the same bounds at
    convergence (docs/synthesis.md, "The event graph"). completion: how open nodes are valued
    (COMPLETION_MODES; "auto": exact trees, so that lower is the policy's exact value, where the
    trust-free route's observation tree fits AUTO_TREE_LEAVES, cluster bounds otherwise;
    docs/synthesis.md, "Open nodes and the acting rule"). clusters: whether cluster policies
    (policies/synthesis/cluster_policy.py) are solved before the search (CLUSTER_MODES); the better
    certified L of the two is returned, and the smaller U.
    """
    check_synthesis_arguments(tau, horizon, belief_rule)
    if completion not in COMPLETION_MODES:
        raise ValueError(f"unknown completion {completion!r}; use one of {', '.join(COMPLETION_MODES)}")
    if clusters not in CLUSTER_MODES:
        raise ValueError(f"unknown clusters {clusters!r}; use one of {', '.join(CLUSTER_MODES)}")
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
        table = PolicyTable(t=[], x=[], q=[], beliefs=np.zeros((0, pomdp.n_trust)), action=[],
                            projected=[])
        lower = upper = strict = 0.0
        note = ("graph distance: acceptance is unreachable" if never else
                f"graph distance: acceptance needs at least {shortest} junctions")
        runs = [{"horizon": horizon, "lower": 0.0, "upper": 0.0, "nodes": 0, "abstraction_root_upper": 0.0,
                 "abstraction_bound": note, "threshold_alternates": 0, "lower_strict_labels": 0.0,
                 "root_dfa_states": sorted(q0), "completion_closed": True,
                 "completion_bounds": False}]
        if horizon is None:
            note = "graph distance: acceptance is unreachable"
    elif horizon is not None:
        symbols = observation_symbols(pomdp, belief_rule)
        order = _cluster_order(tables, symbols, horizon, completion, clusters)
        runs: list[dict] = []

        def cluster_round(until: float) -> tuple[ClusterSolution | None, float]:
            found, found_upper, tried = best_cluster_solution(tables, symbols, sorted(q0), horizon, tau,
                                                              until)
            if found is not None:
                runs.append(_cluster_run(found, found_upper, horizon, tried))
                if on_iteration is not None:
                    on_iteration(found.lower, found_upper)
            return found, found_upper

        cluster, cluster_upper = None, 1.0
        if order == "first":
            cluster, cluster_upper = cluster_round(min(deadline, started + CLUSTER_SHARE * time_limit))
        if cluster is not None and cluster_upper - cluster.lower <= tau:
            lower, upper, table = cluster.lower, cluster_upper, _cluster_table(cluster, pomdp.n_trust)
            strict = cluster.lower
        else:
            search_deadline = (min(deadline, started + SEARCH_SHARE * time_limit) if order == "after"
                               else deadline)
            lower, upper, table, stats = _bounded_search(tables, belief_rule, horizon, tau, suffix_length,
                                                         batch, started, search_deadline,
                                                         on_iteration=on_iteration, compress=compress,
                                                         completion=completion)
            runs.append(stats)
            strict = stats["lower_strict_labels"]
            if order == "after" and upper - lower > tau and time.perf_counter() < deadline:
                cluster, cluster_upper = cluster_round(deadline)
            if cluster is not None:
                upper = min(upper, cluster_upper)
                if cluster.lower > lower:
                    lower, table = cluster.lower, _cluster_table(cluster, pomdp.n_trust)
                    strict = cluster.lower
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
        lower, table, strict, runs = -1.0, None, 0.0, []
        order = _cluster_order(tables, symbols, None, completion, clusters)

        def cluster_phase(lower: float, until: float) -> ClusterSolution | None:
            """Cluster policies for L (accepting within H junctions): growing horizons with the
            first cap (more junctions to come back to a waypoint usually lift L most), then larger
            caps at the best horizon; the one of the largest L above `lower`, if any."""
            best, best_depth = None, None
            rounds = [(shortest + slack, UNBOUNDED_CLUSTER_CAPS[:1]) for slack in UNBOUNDED_CLUSTER_SLACK]
            while rounds:
                depth, caps = rounds.pop(0)
                if upper - lower <= tau or time.perf_counter() >= until:
                    break
                found, _, tried = best_cluster_solution(tables, symbols, sorted(q0), depth, tau, until,
                                                        caps, enough=upper - tau)
                if found is None:
                    break
                runs.append(_cluster_run(found, upper, depth, tried))
                if on_iteration is not None:
                    on_iteration(found.lower, upper)
                if found.lower > lower:
                    best, best_depth, lower = found, depth, found.lower
                if not rounds and best is not None and len(caps) == 1:
                    rounds.append((best_depth, UNBOUNDED_CLUSTER_CAPS))
            return best

        if order == "first":
            found = cluster_phase(lower, min(deadline, started + CLUSTER_SHARE * time_limit))
            if found is not None:
                lower, table, strict = found.lower, _cluster_table(found, pomdp.n_trust), found.lower
        search_deadline = min(deadline, started + SEARCH_SHARE * time_limit) if order == "after" else deadline
        searched_unbounded = False
        for depth in UNBOUNDED_HORIZONS:
            if upper - lower <= tau or (runs and time.perf_counter() >= search_deadline):
                break
            k_run = bounded_suffix_length(tables, symbols.n_changing, suffix_length, depth)
            shared = k_run == k
            run_lower, _, run_table, stats = _bounded_search(
                tables, belief_rule, depth, 0.5 * tau, k_run, batch, started, search_deadline,
                value if shared else None, abstraction if shared else None, on_iteration=on_iteration,
                compress=compress, completion=completion)
            runs.append(stats)
            if run_lower > lower:
                lower, table, strict = run_lower, run_table, stats["lower_strict_labels"]
            if not searched_unbounded and upper - lower > tau:
                searched_unbounded = True
                remaining = max(search_deadline - time.perf_counter(), 0.0)
                run_lower, run_upper, run_table, stats = _bounded_search(
                    tables, belief_rule, None, tau, k, batch, started,
                    time.perf_counter() + 0.25 * remaining, value, abstraction, on_iteration=on_iteration,
                    compress=compress, completion=completion)
                stats["end_component_seconds"] = bound.seconds
                runs.append(stats)
                upper = min(upper, run_upper)
                if run_lower > lower:
                    lower, table, strict = run_lower, run_table, stats["lower_strict_labels"]
        if order == "after" and upper - lower > tau and time.perf_counter() < deadline:
            found = cluster_phase(lower, deadline)
            if found is not None:
                lower, table, strict = found.lower, _cluster_table(found, pomdp.n_trust), found.lower
        lower = max(lower, 0.0)
    policy = BeliefTablePolicy(table, pomdp.town, spec, lower=lower, upper=upper, horizon=horizon)
    stats = {
        "method": "AO*-style expansion of the product belief MDP with suffix-abstraction upper bounds",
        "belief_rule": belief_rule,
        "converged": bool(upper - lower <= tau),
        "tau": tau,
        "runs": runs,
        "policy_rows": table.rows,
        # the returned policy's value with labels read strictly (this machine's labeller): a lower
        # bound of what `evaluate` measures (runs[i]["lower_strict_labels"] is run i's policy's)
        "lower_strict_labels": max(strict, lower),
    }
    if horizon is None:
        stats["unbounded_upper"] = note
        stats["lower_from_horizon"] = max(runs, key=lambda r: r["lower"])["horizon"]
    return SynthesisResult(policy=policy, lower=lower, upper=upper,
                           seconds=time.perf_counter() - started, stats=stats, horizon=horizon,
                           belief_rule=belief_rule)
