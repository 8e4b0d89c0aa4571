"""The trust-free baseline: the shortest route completing a spec's state-only task.

Owns the state-only task of a spec on a town (the product town × DFA of the spec's
state-only projection, every belief literal replaced by true; docs/model.md, "scLDTL"),
its distance-to-completion table, the baseline route and the trust-free policy ("free").

The table is computed once by a backward Dijkstra over the product: for each directed road x
and projected DFA state q (the state after reading the position on x), the shortest distance
(model road lengths) still to drive until the projected DFA accepts, and the next junction
that starts such a shortest completion. Ties are broken by fewer roads, then by the order of
`town.actions`, so following the table from any product state is itself a shortest completion:
the baseline route and every re-plan from a point on it agree.

`free_completion(town, spec)` is the completion a synthesized policy drives wherever it has no row
(policies/routing/aware_table.py) and by which the synthesis values its open nodes: the trust-free
shortest completion while the state-only task is not complete, and after it (a waypoint reached
with too little trust leaves the spec's DFA waiting) the shortest route, in junctions, back to
what the DFA still needs, every label allowed (docs/synthesis.md, "Open nodes and the acting
rule"). The baseline policy "free" and the study's fallback keep the state-only completion.
"""

from __future__ import annotations

import heapq
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from trustroute.core.errors import InputError
from trustroute.networks.town import Town
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.dfa import DFA
from trustroute.policies.logic.spec import Spec, state_only_projection
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

ROUTE_CACHE_SIZE = 4096


@dataclass(frozen=True, eq=False)
class StateOnlyTask:
    """The state-only projection of a spec on a town, with shortest completions.

    next_state[q, x]: projected DFA state after reading road x from state q.
    distance[x, q]: metres still to drive from product state (x, q) to acceptance (inf: impossible).
    next_slot[x, q]: index into town.actions(x) of the first move of a shortest completion
    (-1 when (x, q) is already accepting or cannot complete).
    """

    town: Town
    spec: Spec            # the state-only projection
    dfa: DFA
    initial_state: int    # projected DFA state after reading position 0 (the spec's start road)
    next_state: np.ndarray
    distance: np.ndarray
    hops: np.ndarray
    next_slot: np.ndarray
    road_index: dict[str, int]

    route_cache: OrderedDict = field(default_factory=OrderedDict, repr=False)
    # next_junction per (road, q): episodes ask it at every junction (at most roads × states entries)
    junction_cache: dict = field(default_factory=dict, repr=False)

    def projected_state(self, route: Sequence[str]) -> int:
        """Projected DFA state after reading every road of `route` (route[0] = position 0)."""
        # Evaluation asks for the same route once per observation branch: cached by route.
        key = tuple(route)
        cached = self.route_cache.get(key)
        if cached is not None:
            return cached
        q = int(self.dfa.initial)
        for road in key:
            q = int(self.next_state[q, self.road_index[road]])
        self.route_cache[key] = q
        if len(self.route_cache) > ROUTE_CACHE_SIZE:
            self.route_cache.popitem(last=False)
        return q

    def same_moves(self, other: StateOnlyTask) -> bool:
        """True when `other` reads every route into the same state and moves the same from it (the
        same town's roads, DFA start, transitions and shortest-completion moves)."""
        return self is other or (
            self.town.content_hash == other.town.content_hash and self.road_index == other.road_index
            and int(self.dfa.initial) == int(other.dfa.initial)
            and np.array_equal(self.next_state, other.next_state)
            and np.array_equal(self.next_slot, other.next_slot))

    def next_junction(self, road: str, q: int) -> str | None:
        """First junction of the shortest completion from (road, q); None if complete or impossible."""
        key = (road, q)
        if key in self.junction_cache:
            return self.junction_cache[key]
        slot = int(self.next_slot[self.road_index[road], q])
        junction = None if slot < 0 else self.town.actions(road)[slot]
        self.junction_cache[key] = junction
        return junction

    def completion(self, road: str, q: int) -> list[str] | None:
        """Shortest completion from product state (road, q): roads from `road` (included) on."""
        x = self.town.state_index(road)
        if not np.isfinite(self.distance[x, q]):
            return None
        route = [road]
        while not self.dfa.accepting[q]:
            junction = self.next_junction(route[-1], q)
            assert junction is not None  # finite distance and not accepting: a move exists
            nxt = self.town.successor(route[-1], junction)
            q = int(self.next_state[q, self.town.state_index(nxt)])
            route.append(nxt)
        return route


def _uniform_beliefs(count: int) -> np.ndarray:
    # The projection has no belief atoms, so any belief labels the same; 7 = the Muir scale.
    return np.full((count, 7), 1.0 / 7.0)


def completion_distances(successors: list[list[int]], lengths: np.ndarray, next_state: np.ndarray,
                         accepting: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(metres, roads) [n_x, n_q] of the shortest completion from each product state (x, q): a
    backward Dijkstra from every accepting product state, keys (metres, roads) lexicographic."""
    n_x, n_q = next_state.shape[1], next_state.shape[0]
    predecessors: list[list[tuple[int, int]]] = [[] for _ in range(n_x * n_q)]
    for x in range(n_x):
        for q in range(n_q):
            if accepting[q]:
                continue  # absorbing targets: no need to leave them
            for x2 in successors[x]:
                q2 = int(next_state[q, x2])
                predecessors[x2 * n_q + q2].append((x, q))
    distance = np.full((n_x, n_q), np.inf)
    hops = np.full((n_x, n_q), np.iinfo(np.int64).max, dtype=np.int64)
    queue: list[tuple[float, int, int, int]] = []
    for accepted in np.flatnonzero(accepting):
        for x in range(n_x):
            distance[x, accepted] = 0.0
            hops[x, accepted] = 0
            queue.append((0.0, 0, x, int(accepted)))
    heapq.heapify(queue)
    while queue:
        dist, hop, x2, q2 = heapq.heappop(queue)
        if (dist, hop) > (distance[x2, q2], hops[x2, q2]):
            continue
        for x, q in predecessors[x2 * n_q + q2]:
            key = (dist + lengths[x2], hop + 1)
            if key < (distance[x, q], hops[x, q]):
                distance[x, q], hops[x, q] = key
                heapq.heappush(queue, (key[0], key[1], x, q))
    return distance, hops


def completion_slots(successors: list[list[int]], lengths: np.ndarray, next_state: np.ndarray,
                     accepting: np.ndarray, distance: np.ndarray, hops: np.ndarray) -> np.ndarray:
    """int [n_x, n_q]: the action slot of the shortest completion's first move (-1: none)."""
    n_x, n_q = distance.shape
    next_slot = np.full((n_x, n_q), -1, dtype=np.int64)
    for x in range(n_x):
        for q in range(n_q):
            if accepting[q] or not np.isfinite(distance[x, q]):
                continue
            best = None
            for slot, x2 in enumerate(successors[x]):
                q2 = int(next_state[q, x2])
                key = (lengths[x2] + distance[x2, q2], 1 + int(hops[x2, q2]))
                # Strictly fewer hops among equal distances guarantees the greedy walk terminates.
                if np.isfinite(key[0]) and (best is None or key < best[0]):
                    best = (key, slot)
            if best is None:
                raise TypeError(f"no successor of road {x} completes the spec from DFA state {q} "
                                "though its distance is finite")
            next_slot[x, q] = best[1]
    return next_slot


def build_state_only_task(town: Town, spec: Spec) -> StateOnlyTask:
    """Project `spec` onto its state atoms and compute shortest completions on `town`."""
    projected = state_only_projection(spec)
    compiled = compile_spec(projected, town)
    dfa, labeller = compiled.dfa, compiled.labeller
    n_x, n_q = len(town.states), int(dfa.n_states)
    q_grid, x_grid = np.meshgrid(np.arange(n_q), np.arange(n_x), indexing="ij")
    next_state = np.asarray(
        labeller.step(q_grid.ravel(), x_grid.ravel(), _uniform_beliefs(n_q * n_x)), dtype=np.int64
    ).reshape(n_q, n_x)

    successors = [[town.state_index(s) for s in town.successors(r)] for r in town.states]
    lengths = np.array([town.length(r) for r in town.states])
    accepting = np.asarray(dfa.accepting, dtype=bool)
    distance, hops = completion_distances(successors, lengths, next_state, accepting)
    next_slot = completion_slots(successors, lengths, next_state, accepting, distance, hops)
    initial = int(next_state[int(dfa.initial), town.state_index(spec.start)])
    for array in (next_state, distance, hops, next_slot):
        array.setflags(write=False)
    return StateOnlyTask(town=town, spec=projected, dfa=dfa, initial_state=initial,
                         next_state=next_state, distance=distance, hops=hops, next_slot=next_slot,
                         road_index={road: i for i, road in enumerate(town.states)})


def state_only_task(town: Town, spec: Spec) -> StateOnlyTask:
    """`build_state_only_task`, built once per compiled spec and held by it."""
    compiled = compile_spec(spec, town)
    task = compiled.derived.get("state_only_task")
    if task is None:
        task = compiled.derived["state_only_task"] = build_state_only_task(town, spec)
    return task


def label_free_distance(successors: np.ndarray, next_q: np.ndarray, accepting: np.ndarray,
                        rejecting: np.ndarray) -> np.ndarray:
    """int [n_x, n_q]: fewest junctions from (x, q) to an accepting DFA state in the road × DFA
    graph with every belief-label value allowed (a breadth-first search backwards from acceptance;
    UNREACHABLE where acceptance cannot be reached). successors [n_x, slots] (road or -1);
    next_q [n_q, n_x, 2**m] (CompiledSpec.label_table); accepting, rejecting bool [n_q]."""
    n_x, n_q = successors.shape[0], next_q.shape[0]
    distance = np.full((n_x, n_q), UNREACHABLE, dtype=np.int64)
    distance[:, accepting] = 0
    live = ~(accepting | rejecting)
    # edges (x, q) -> (x2, next_q[q, x2, bits]) for every bits; reversed per layer.
    src_x = np.repeat(np.arange(n_x), successors.shape[1])
    dst_x = successors.ravel()
    ok = dst_x >= 0
    src_x, dst_x = src_x[ok], dst_x[ok]
    q2 = next_q[:, dst_x, :].transpose(1, 0, 2)          # [edges, n_q, bits]
    level = 0
    frontier = distance == 0
    while frontier.any():
        level += 1
        # (x, q) gets `level` if some successor (x2, q2) is on the frontier
        reached = frontier[dst_x[:, None, None], q2].any(axis=2)   # [edges, n_q]
        hit = np.zeros((n_x, n_q), dtype=bool)
        np.logical_or.at(hit, src_x, reached)
        new = hit & live & (distance == UNREACHABLE)
        distance[new] = level
        frontier = new
    return distance


UNREACHABLE = np.iinfo(np.int64).max // 4


@dataclass(frozen=True, eq=False)
class FreeCompletion:
    """The free completion's move per product context (x, q, p): road, spec DFA state, state-only
    task state (module docstring).

    slot[x, q, p]: index into town.actions(road x), always a legal move. While the state-only task
    is not complete (task.next_slot[x, p] >= 0) it is the task's move, the same for every q; after
    it (or where it cannot be completed) the first move of a shortest route to acceptance in the
    road × DFA graph with every label allowed (fewest junctions, `distance`; ties: slot order);
    the first legal move where acceptance is unreachable. `returns[x, q]` is that second move.
    """

    task: StateOnlyTask
    slot: np.ndarray        # [n_x, n_q, n_p]
    returns: np.ndarray     # [n_x, n_q]
    distance: np.ndarray    # [n_x, n_q] junctions to acceptance, every label allowed

    def junction(self, road: str, q: int, p: int) -> str:
        """The completion's next junction at (road, DFA state q, task state p)."""
        x = self.task.road_index[road]
        return self.task.town.actions(road)[int(self.slot[x, q, p])]


def build_free_completion(town: Town, spec: Spec) -> FreeCompletion:
    """The free completion of `spec` on `town` (FreeCompletion)."""
    task = state_only_task(town, spec)
    compiled = compile_spec(spec, town)
    _, next_q = compiled.label_table()
    accepting = np.asarray(compiled.accepting, dtype=bool)
    rejecting = np.asarray(compiled.rejecting, dtype=bool) & ~accepting
    n_x = len(town.states)
    successors = town.successor_table
    distance = label_free_distance(successors, next_q, accepting, rejecting)
    # distance after entering x2 from q, with the most favourable label there: [n_q, n_x]
    entered = distance[np.arange(n_x)[None, :, None], next_q].min(axis=2)
    cost = np.where(successors[:, None, :] >= 0,
                    entered[:, np.maximum(successors, 0)].transpose(1, 0, 2), UNREACHABLE)  # [x, q, s]
    returns = np.where(cost.min(axis=2) < UNREACHABLE, cost.argmin(axis=2), 0).astype(np.int64)
    task_slot = task.next_slot                                                    # [n_x, n_p]
    slot = np.where(task_slot[:, None, :] >= 0, task_slot[:, None, :], returns[:, :, None])
    for array in (slot, returns, distance):
        array.setflags(write=False)
    return FreeCompletion(task=task, slot=slot, returns=returns, distance=distance)


def free_completion(town: Town, spec: Spec) -> FreeCompletion:
    """`build_free_completion`, built once per compiled spec and held by it."""
    compiled = compile_spec(spec, town)
    completion = compiled.derived.get("free_completion")
    if completion is None:
        completion = compiled.derived["free_completion"] = build_free_completion(town, spec)
    return completion


def completion_route(town: Town, spec: Spec, route: Sequence[str]) -> list[str] | None:
    """Shortest route completing the remaining state-only task after driving `route`.

    Starts with route[-1]; just [route[-1]] when the state-only task is already complete;
    None when it can no longer be completed.
    """
    task = state_only_task(town, spec)
    return task.completion(route[-1], task.projected_state(route))


def baseline_route(town: Town, spec: Spec) -> list[str]:
    """The trust-free baseline: shortest route (start road first) satisfying the state-only projection."""
    task = state_only_task(town, spec)
    route = task.completion(spec.start, task.initial_state)
    if route is None:
        raise InputError(spec.source_path or spec.name, "formula",
                         f"no route from {spec.start} satisfies the state-only part of the spec on "
                         f"this town", "check the spec's state atoms and start road against the town")
    return route


class TrustFreePolicy(RoutingPolicy):
    """Drive the shortest state-only completion from wherever the vehicle is ("free").

    On the baseline route this follows the baseline route; off it (a context route that
    differs) it re-plans from the current road and the projected DFA state of the route.
    `finished(context)` is True once the state-only task is complete (the destination) or
    can no longer be completed; the episode then ends.
    """

    name = "free"

    def __init__(self, task: StateOnlyTask) -> None:
        self.task = task

    def route_determined(self, context: DecisionContext) -> bool:
        """Always: the trust-free policy looks at the roads driven only (lets evaluation batch)."""
        return True

    def finished(self, context: DecisionContext) -> bool:
        return self.task.next_junction(context.road, self.task.projected_state(context.route)) is None

    def next_junction(self, context: DecisionContext) -> str:
        junction = self.task.next_junction(context.road, self.task.projected_state(context.route))
        # Asked after the task is done: any legal move; the episode should have ended.
        return junction if junction is not None else self.task.town.actions(context.road)[0]


def trust_free_policy(town: Town, spec: Spec) -> TrustFreePolicy:
    """The trust-free baseline as a RoutingPolicy named "free"."""
    return TrustFreePolicy(state_only_task(town, spec))
