"""The one unfolding of the episode tree, level by level, for every evaluation.

One level per junction: a node is one history of observations (its road, its probability, its
route and its node state: policies/evaluation/node_state.py). At every level, in this order:
1. the ledger (policies/evaluation/ledgers.py) ends the nodes the DFA has decided (and, for a
   bounded reading, every node at the cap), and past the deadline cuts every open node;
2. it cuts the open nodes too unlikely to follow;
3. the actor decides the rest: the episode rules around a routing policy (`EpisodeActor`:
   destination, cap, fallback; one decision per distinct route and node state) or a policy that
   picks the next road for a batch of nodes at once (`SlotActor`);
4. every moved node branches on every observation (h, e) at its next road (the node state's
   filter); `Limits.chunk` nodes at a time, and with `Limits.paced` a batch is not begun when, at
   the last batch's pace, it would end past the deadline (the nodes not moved are cut). The
   children are written, observation by observation, into arrays allocated once per level
   (`Children`): a level never holds every observation's children and their joined copy at once;
5. with `Limits.merge`, children at the same road and node state on routes the policy reads
   alike (`RoutingPolicy.route_memory`) become one node, their masses summed;
6. the ledger keeps at most its budget of nodes (the rest are cut), and the routes and words no
   kept node holds are forgotten (`Frontier.compacted`).
Cut mass is unknown: it is the width of [lower, upper].
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from trustroute.core.errors import InputError
from trustroute.networks.town import Town
from trustroute.policies.belief.trust_state_filter import distinct_rows, split_by_words
from trustroute.policies.evaluation.node_state import HiddenState, NodeState
from trustroute.policies.model.trust_pomdp import row_blocks
from trustroute.policies.routing.episode_rules import decide
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy
from trustroute.policies.work_clock import now as clock_now
from trustroute.policies.work_clock import spend


@dataclass(frozen=True, eq=False)
class Frontier:
    """The open nodes of one level: road index, probability, route id and node state per row."""

    road: np.ndarray
    probability: np.ndarray
    route_id: np.ndarray
    state: NodeState

    @property
    def size(self) -> int:
        return int(self.probability.size)

    def take(self, rows: np.ndarray | slice) -> Frontier:
        return Frontier(road=self.road[rows], probability=self.probability[rows],
                        route_id=self.route_id[rows], state=self.state.take(rows))

    @property
    def bytes_per_node(self) -> float:
        """Bytes of its arrays per node (0 without nodes)."""
        total = self.road.nbytes + self.probability.nbytes + self.route_id.nbytes + self.state.nbytes
        return total / self.size if self.size else 0.0

    def compacted(self, actor: Actor) -> Frontier:
        """The same nodes, the routes (Actor.compact) and the words (NodeState.compact) none of them
        holds forgotten: what the unfolding keeps between levels is its frontier, not every history
        it has seen."""
        return replace(self, route_id=actor.compact(self.route_id), state=self.state.compact())

    def allocate(self, rows: int) -> Frontier:
        """Arrays for `rows` nodes like these, their contents unset (`put` fills them)."""
        return Frontier(road=np.empty(rows, dtype=self.road.dtype), probability=np.empty(rows),
                        route_id=np.empty(rows, dtype=self.route_id.dtype), state=self.state.allocate(rows))

    def put(self, at: slice, part: Frontier) -> None:
        """Write the nodes of `part` into rows `at` of these arrays (one of `allocate`'s)."""
        self.road[at], self.probability[at], self.route_id[at] = part.road, part.probability, part.route_id
        self.state.put(at, part.state)


def joint_beliefs(state: NodeState) -> np.ndarray:
    """J(θ, q) of every row; only a node state with a hidden DFA state has them."""
    if not isinstance(state, HiddenState):
        raise AttributeError(f"{type(state).__name__} has no joint beliefs (the DFA state is observed)")
    return state.joint


def root(start: int, state: NodeState) -> Frontier:
    return Frontier(road=np.array([start], dtype=np.int64), probability=np.ones(1),
                    route_id=np.zeros(1, dtype=np.int64), state=state)


@dataclass(frozen=True)
class Moves:
    """An actor's decisions for a batch of nodes: finished here, the fallback drove, next road."""

    finished: np.ndarray
    fired: np.ndarray
    next_road: np.ndarray


class BatchedPolicy(Protocol):
    """A policy told each level's nodes with their joint beliefs at once before it is asked node
    by node (routing.trust_state_table.JointTablePolicy)."""

    def prefetch(self, t: int, x: np.ndarray, joint: np.ndarray, beliefs: np.ndarray) -> None: ...

    def forget_prefetched(self) -> None: ...


class Actor(Protocol):
    def act(self, level: int, frontier: Frontier) -> Moves: ...

    def moved(self, route_id: np.ndarray, next_road: np.ndarray) -> np.ndarray:
        """Route ids of the nodes after driving `next_road`."""

    def memory(self, frontier: Frontier) -> np.ndarray | None:
        """A column for merging: equal for routes the policy reads alike (None: no routes)."""

    def compact(self, route_id: np.ndarray) -> np.ndarray:
        """The route ids of the open nodes once the routes none of them is on are forgotten."""

    def done(self) -> None: ...


class Ledger(Protocol):
    fallback_mass: float

    def settle(self, frontier: Frontier, level: int, out_of_time: bool) -> np.ndarray | None: ...

    def prune(self, frontier: Frontier, alive: np.ndarray, level: int) -> np.ndarray: ...

    def end(self, frontier: Frontier, rows, reason: str, level: int) -> None: ...

    def cut(self, frontier: Frontier, rows, level: int, why: str) -> None: ...

    def trim(self, frontier: Frontier, level: int) -> np.ndarray | None: ...


def extend_routes(routes: list[tuple[str, ...]], route_id: np.ndarray, chosen: np.ndarray,
                  states: tuple[str, ...] | list[str]) -> np.ndarray:
    """Append one route per distinct (old route, next road) to `routes`; the new ids, per node."""
    n_states = len(states)
    pair = route_id * n_states + chosen
    unique_pairs, pair_inverse = np.unique(pair, return_inverse=True)
    pair_ids = np.arange(len(routes), len(routes) + unique_pairs.size)
    for rid, x2 in zip((unique_pairs // n_states).tolist(), (unique_pairs % n_states).tolist(),
                       strict=True):
        routes.append(routes[rid] + (states[x2],))
    return pair_ids[pair_inverse]


@dataclass(eq=False)
class EpisodeActor:
    """A routing policy under the episode rules (policies/routing/episode_rules.py).

    The policy is asked once per distinct (route, DFA state told, NodeState.decision_columns). A
    policy that says its decision on a route is the same for every belief and non-accepting DFA
    state (`route_determined`: the fallback phase, the trust-free route) is asked once per route for
    the nodes told a non-accepting state (an accepting one may switch the fallback off). A policy that
    decides batches of nodes at once (JointTablePolicy.prefetch) is given each level's nodes with
    their joint beliefs in one call first."""

    policy: RoutingPolicy
    town: Town
    max_junctions: int
    fallback_level: int | None
    accepting: np.ndarray                      # bool [n_q]: the told states that are accepting
    batched: BatchedPolicy | None = None
    routes: list = field(default_factory=list)
    memory_ids: dict = field(default_factory=dict)
    successor_index: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        town = self.town
        self.successor_index = {(x, j): town.state_index(town.successor(road, j))
                                for x, road in enumerate(town.states) for j in town.actions(road)}

    def decide_node(self, context: DecisionContext, road: int, level: int) -> tuple[bool, bool, int]:
        """(finished here, the fallback first drives here, next road index or -1) by the episode rules;
        road is the index of context.road."""
        decision = decide(self.policy, context, self.town, self.max_junctions)
        if decision.end is not None:
            return decision.end == "destination", False, -1
        return (False, self.fallback_level == level and decision.fallback,
                self.successor_index[(road, decision.junction)])

    def context(self, frontier: Frontier, told: np.ndarray, row: int) -> DecisionContext:
        state = frontier.state
        return DecisionContext(route=self.routes[int(frontier.route_id[row])], dfa_state=int(told[row]),
                               belief=state.belief[row], joint=state.joint_row(row))

    def act(self, level: int, frontier: Frontier) -> Moves:
        state = frontier.state
        if self.batched is not None:       # given with joint-belief node states only
            self.batched.prefetch(level, frontier.road, joint_beliefs(state), state.belief)
        told = state.told()
        told_accepting = self.accepting[told]
        n = frontier.size
        out = (np.zeros(n, dtype=bool), np.zeros(n, dtype=bool), np.full(n, -1, dtype=np.int64))
        unique_routes, inverse = np.unique(frontier.route_id, return_inverse=True)
        order = np.argsort(inverse, kind="stable")
        bounds = np.searchsorted(inverse[order], np.arange(unique_routes.size + 1))
        one_by_one = np.zeros(n, dtype=bool)
        for r in range(unique_routes.size):
            members = order[bounds[r]:bounds[r + 1]]
            rest = self.decide_route(level, frontier, told, members[~told_accepting[members]], out)
            one_by_one[members if rest else members[told_accepting[members]]] = True
        self.decide_nodes(level, frontier, told, np.flatnonzero(one_by_one), out)
        return Moves(*out)

    def decide_nodes(self, level: int, frontier: Frontier, told: np.ndarray, rows: np.ndarray,
                     out: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        """Decide `rows` (in order), asking the policy once per distinct (route, DFA state told,
        NodeState.decision_columns), route by route in id order and within a route in the order of
        their first rows. The rows are grouped in arrays (trust_state_filter.distinct_rows), not
        by a Python key per row: a level of a million rows holds no million keys."""
        if rows.size == 0:
            return
        columns = [frontier.route_id[:, None], told[:, None], *frontier.state.decision_columns()]
        if rows.size < frontier.size:
            columns = [column[rows] for column in columns]
        first, inverse = distinct_rows(*columns)
        heads = rows[first]
        finished, fired = np.zeros(first.size, dtype=bool), np.zeros(first.size, dtype=bool)
        next_road = np.empty(first.size, dtype=np.int64)
        roads = frontier.road
        for g in np.lexsort((heads, frontier.route_id[heads])).tolist():
            k = int(heads[g])
            finished[g], fired[g], next_road[g] = self.decide_node(self.context(frontier, told, k),
                                                                   int(roads[k]), level)
        out[0][rows], out[1][rows], out[2][rows] = finished[inverse], fired[inverse], next_road[inverse]

    def decide_route(self, level: int, frontier: Frontier, told: np.ndarray, members: np.ndarray,
                     out: tuple[np.ndarray, np.ndarray, np.ndarray]) -> bool:
        """Decide `members` (one route, told non-accepting states) at once if the policy's decision
        there is the route's; whether they are still to be decided one by one."""
        if members.size == 0:
            return True
        first = int(members[0])
        context = self.context(frontier, told, first)
        if not self.policy.route_determined(context):
            return True
        out[0][members], out[1][members], out[2][members] = self.decide_node(
            context, int(frontier.road[first]), level)
        return False

    def moved(self, route_id: np.ndarray, next_road: np.ndarray) -> np.ndarray:
        return extend_routes(self.routes, route_id, next_road, self.town.states)

    def compact(self, route_id: np.ndarray) -> np.ndarray:
        """Forget the routes no node of `route_id` is on; their ids after it. Every route a level's
        nodes are on is new (`moved` gives each child the route it drove), so what is kept is the
        routes of the open nodes alone. Ids keep their order (a route's new id is the number of
        routes kept before it), so whatever groups or orders nodes by route does so as before, and
        a route added later still gets a larger id."""
        held, inverse = np.unique(route_id, return_inverse=True)
        if held.size == len(self.routes):
            return route_id
        self.routes = [self.routes[r] for r in held.tolist()]
        return inverse.reshape(route_id.shape)

    def memory(self, frontier: Frontier) -> np.ndarray:
        unique_routes, route_inverse = np.unique(frontier.route_id, return_inverse=True)
        return np.array([self.memory_ids.setdefault(self.policy.route_memory(self.routes[r]),
                                                    len(self.memory_ids))
                         for r in unique_routes.tolist()], dtype=float)[route_inverse]

    def done(self) -> None:
        if self.batched is not None:
            self.batched.forget_prefetched()


@dataclass(frozen=True, eq=False)
class SlotActor:
    """A policy that picks the action slot of a batch of nodes from (junctions driven, road, joint
    belief, AV belief) alone (`action_slots`, routing.trust_state_table.JointTablePolicy), without
    episode rules: nodes never finish and the fallback never drives; routes are not kept."""

    slots: Callable[[int, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
    successor_table: np.ndarray

    def act(self, level: int, frontier: Frontier) -> Moves:
        state = frontier.state
        slots = self.slots(level, frontier.road, joint_beliefs(state), state.belief)
        n = frontier.size
        return Moves(np.zeros(n, dtype=bool), np.zeros(n, dtype=bool),
                     self.successor_table[frontier.road, slots])

    def moved(self, route_id: np.ndarray, next_road: np.ndarray) -> np.ndarray:
        return route_id

    def memory(self, frontier: Frontier) -> None:
        return None

    def compact(self, route_id: np.ndarray) -> np.ndarray:
        return route_id

    def done(self) -> None:
        return None


@dataclass(frozen=True)
class Limits:
    """How far the unfolding goes: the junction cap, the deadline (on the synthesis' clock,
    policies/work_clock.py, time.perf_counter() outside a synthesis under a work limit; every node
    still open at a level begun past it is cut), batches of `chunk` nodes (None: the level at once)
    paced against the deadline, merging of equal children."""

    max_junctions: int
    deadline: float | None = None
    chunk: int | None = None
    paced: bool = False
    merge: bool = False


@dataclass(eq=False)
class Pace:
    """The last batch's duration and the last merge's seconds per row, to foresee a late one."""

    deadline: float | None
    batch_seconds: float = 0.0
    merge_rate: float = 0.0

    def batch_is_late(self, began: float) -> bool:
        return self.deadline is not None and began + self.batch_seconds > self.deadline

    def merge_is_late(self, rows: int) -> bool:
        return self.deadline is not None and clock_now() + self.merge_rate * rows > self.deadline


@dataclass(frozen=True, eq=False)
class Counts:
    nodes: int
    max_frontier: int


# units of work (policies/work_clock.py) per node moved (its decision and branching) and per node merged
ROW_UNITS = 100
MERGE_UNITS = 5

OUTCOMES_WITH_PERFORMANCE = ((0, 0), (0, 1), (1, 0), (1, 1))
OUTCOMES = ((0, 0), (1, 0))


def outcomes(depends_on_performance: bool) -> tuple[tuple[int, int], ...]:
    """The observations (h, e) at a road: e is observed only when the driver's trust reads it."""
    return OUTCOMES_WITH_PERFORMANCE if depends_on_performance else OUTCOMES


@dataclass(eq=False)
class Children:
    """A level's children, written batch by batch and observation by observation into arrays
    allocated at the first (Frontier.allocate), for as many rows as can follow: exactly the
    children of a level moved in one batch. `later`: at most how many rows the batches after the
    current one add."""

    frontier: Frontier | None = None
    size: int = 0
    later: int = 0

    def add(self, part: Frontier, to_come: int) -> None:
        """Append `part`; at most `to_come` more rows follow it in this batch."""
        if self.frontier is None:
            self.frontier = part.allocate(part.size + to_come + self.later)
        self.frontier.put(slice(self.size, self.size + part.size), part)
        self.size += part.size

    def joined(self) -> Frontier | None:
        """The children added, their node states stepped (NodeState.stepped); None: no batch moved."""
        if self.frontier is None:
            return None
        children = self.frontier
        if self.size < children.size:
            children = children.take(slice(0, self.size))
        return replace(children, state=children.state.stepped(children.road))


def branch(frontier: Frontier, next_road: np.ndarray, route_id: np.ndarray,
           observations: tuple[tuple[int, int], ...], children: Children) -> None:
    """Add the children of every node, observation by observation (the impossible ones left out),
    to `children`. Each observation's probabilities are computed once: they size the children's
    arrays before the first observation's are written, and they are the children's masses."""
    p_obs = [frontier.state.observation_probability(next_road, h, e) for h, e in observations]
    counts = [int(np.count_nonzero(p > 0)) for p in p_obs]
    for k, (h, e) in enumerate(observations):
        children.add(observed(frontier, next_road, route_id, (h, e), p_obs[k]), to_come=sum(counts[k + 1:]))


def observed(frontier: Frontier, next_road: np.ndarray, route_id: np.ndarray, observation: tuple[int, int],
             p_obs: np.ndarray) -> Frontier:
    """The children of every node where `observation` (h, e) is observed at its next road, if
    possible there (`p_obs`: its probability per node, `NodeState.observation_probability`)."""
    state = frontier.state.children(next_road, *observation, p_obs)
    possible = p_obs > 0
    return Frontier(road=next_road[possible], probability=frontier.probability[possible] * p_obs[possible],
                    route_id=route_id[possible], state=state)


def merged(frontier: Frontier, memory: np.ndarray | None) -> Frontier:
    """One node per distinct (road, node state, route memory) and word of the AV belief, its mass
    the sum of theirs."""
    columns = [frontier.road[:, None].astype(float), frontier.state.merge_columns()]
    if memory is not None:
        columns.append(memory[:, None])
    first, inverse = split_by_words(*distinct_rows(*columns),
                                    frontier.state.word)
    probability = np.bincount(inverse, weights=frontier.probability)
    return replace(frontier.take(first), probability=probability)


def chunks(size: int, chunk: int | None) -> Iterator[slice]:
    return row_blocks(size, size if chunk is None else chunk)


def move(level: int, frontier: Frontier, actor: Actor, ledger: Ledger, limits: Limits,
         observations: tuple[tuple[int, int], ...], children: Children) -> bool:
    """Decide one batch of open nodes and add their children; False when the episode tree ends here
    (the cap, or no node goes on)."""
    moves = actor.act(level, frontier)
    ledger.end(frontier, moves.finished, "destination", level)
    if level == limits.max_junctions:
        ledger.end(frontier, ~moves.finished, "cap", level)
        return False
    ledger.fallback_mass += float(frontier.probability[moves.fired].sum())
    going = ~moves.finished
    if not going.any():
        return False
    if not going.all():
        frontier = frontier.take(going)
    next_road = moves.next_road[going]
    branch(frontier, next_road, actor.moved(frontier.route_id, next_road), observations, children)
    return True


# What a junction needs at its peak, in copies of its children's arrays (histories x observations x
# bytes per history, `check_memory`): the children (one set of arrays, `Children`), the nodes moved,
# one observation's children before they are put in, the merge's columns and their sort, the trim's
# copy of the nodes kept, and the words of the exact labels with their lookup. Measured on the
# unbounded phi1 policy at 20,000, 80,000 and 320,000 histories per junction (docs/model.md): one
# junction's own growth is at most 3.5 copies in resident memory (its peak from the check to the
# next) and at most 4.0 in allocations (tracemalloc), but the resident peak of the whole run above
# the process before its first junction is 5.2-6.3 copies of its largest junction (the retained
# heap, the words and routes held between junctions, the run's fixed costs; most at the smallest
# budget). A refusal's suggested budget is one whole run at that budget, so the constant bounds the
# whole run's. (Renumbering the words allocates in proportion to the words held, not to the
# junction's histories: 12 copies of a late, small junction at 320,000, out of memory that the larger
# junctions before it freed and the process still holds, so resident memory does not grow there.)
PEAK_COPIES = 7


def available_memory() -> int | None:
    """Bytes the kernel can give without swapping (MemAvailable); None where it does not say."""
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def check_memory(level: int, frontier: Frontier, n_observations: int) -> None:
    """Refuse, before it is allocated, a level whose children would not fit in the memory
    available: an InputError naming the node budget that fits."""
    available = available_memory()
    per_child = PEAK_COPIES * frontier.bytes_per_node
    children = frontier.size * n_observations
    if available is None or children * per_child <= available:
        return
    fits = int(available / (n_observations * per_child))
    raise InputError("--max-nodes", "", f"junction {level + 1} would branch {frontier.size:,} histories "
                     f"into up to {children:,}, about {children * per_child / 1e9:.1f} GB with "
                     f"{available / 1e9:.1f} GB of memory available",
                     f"pass --max-nodes {max(fits, 1):,} or less, or a lower --max-junctions")


def advance(level: int, frontier: Frontier, actor: Actor, ledger: Ledger, limits: Limits, pace: Pace,
            observations: tuple[tuple[int, int], ...]) -> Frontier | None:
    """The next level's frontier from the open nodes of this one (None: the unfolding stops)."""
    check_memory(level, frontier, len(observations))
    moved = Children()
    late = False
    for rows in chunks(frontier.size, limits.chunk):
        began = clock_now()
        late = limits.paced and pace.batch_is_late(began)
        if late:
            # Out of time within the level: the nodes not moved yet are cut.
            ledger.cut(frontier, slice(rows.start, None), level, "past_deadline")
            break
        moved.later = max(frontier.size - rows.stop, 0) * len(observations)
        if not move(level, frontier.take(rows), actor, ledger, limits, observations, moved):
            return None
        spend(ROW_UNITS * (min(rows.stop, frontier.size) - rows.start))
        pace.batch_seconds = clock_now() - began
    children = moved.joined()
    if children is None:
        return None
    del moved       # the children's DFA states before the step are not held from here
    if limits.paced and (late or pace.merge_is_late(children.size)):
        # The children of the nodes moved are cut.
        ledger.cut(children, slice(None), level, "past_deadline")
        return None
    if limits.merge:
        began = clock_now()
        unmerged = children.size
        children = merged(children, actor.memory(children))
        spend(MERGE_UNITS * unmerged)
        pace.merge_rate = (clock_now() - began) / unmerged
    return children


def unfold(frontier: Frontier, actor: Actor, ledger: Ledger, limits: Limits,
           observations: tuple[tuple[int, int], ...]) -> Counts:
    """Run the unfolding from `frontier` (the root); the ledger holds the result."""
    nodes = max_frontier = frontier.size
    pace = Pace(limits.deadline)
    for level in range(limits.max_junctions + 1):
        out_of_time = limits.deadline is not None and level > 0 and clock_now() > limits.deadline
        alive = ledger.settle(frontier, level, out_of_time)
        if alive is None:
            break
        alive = ledger.prune(frontier, alive, level)
        if not alive.any():
            break
        if not alive.all():
            frontier = frontier.take(np.flatnonzero(alive))
        following = advance(level, frontier, actor, ledger, limits, pace, observations)
        if following is None:
            break
        # held from here: the children alone (not the nodes moved), and once trimmed, the nodes kept
        frontier, following = following, None
        kept = ledger.trim(frontier, level)
        if kept is not None:
            frontier = frontier.take(kept)
        frontier = frontier.compacted(actor)
        nodes += frontier.size
        max_frontier = max(max_frontier, frontier.size)
    actor.done()
    return Counts(nodes=nodes, max_frontier=max_frontier)
