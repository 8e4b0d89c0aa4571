"""The town compressed to its event graph: macro moves between the roads where something can happen.

Along a product history (x, q, p, b) — road, DFA state, state-only task state, belief — the only
roads where the future can differ are *event roads*:

* roads whose incident can change the belief or has more than one observation (the belief moves,
  or the history branches);
* roads where the DFA can leave q under some letter the road can carry (every valuation of the
  belief atoms: a belief atom may be true on any road; an empty letter can move a `U`);
* roads where the state-only task (the trust-free completion's state p) moves.

Every other road is *quiet* for (q, p): its incident has a single observation of probability
exactly 1 that leaves the belief unchanged bit for bit (`TrustPOMDP.preserves_belief`, e.g. the
default model's `none`), and neither q nor p moves whatever the label. Between two event roads the
vehicle therefore only spends junctions: driving a path of quiet roads changes nothing but the
clock. A bounded-horizon reachability value never decreases with more junctions left, so among
the quiet paths from a road to the same event road the shortest dominates (docs/synthesis.md,
"The event graph"). A macro move is "drive the shortest quiet path to event road e"; its cost is
the path's junction count.

`EventGraph.moves(x, q, p)` lists them for one product context, and also the trust-free
completion's own macro move (follow its junctions until the first event road), which the returned
policy drives wherever it has no row: a separate slot unless it has the same target and length as
a shortest move (then both reach the same product node). Where no road can be quiet the moves are
the town's junctions in their own order, so the search is the plain one.

`chains_only`: pass through only the quiet roads with a single junction. Then the moves of a road
are its junctions, each followed down the chain of such roads (never more moves than junctions,
and no dominance argument needed); the full event graph can have many more moves per context
than junctions where quiet roads branch (every event road around a quiet region is a target).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from trustroute.policies.belief.product_mdp import ProductTables
from trustroute.policies.routing.free import StateOnlyTask
from trustroute.policies.synthesis.belief_cells import ObservationSymbols


@dataclass(frozen=True, eq=False)
class MacroMoves:
    """The macro moves of one product context (x, q, p).

    target[a]: the event road reached; length[a]: junctions driven to reach it (>= 1);
    path[a]: the roads driven before the target, x first, with the junction slot taken on each
    ((road, slot) pairs; the vehicle's decisions). free: index of the trust-free completion's move;
    its target is -1 when that completion never reaches an event road (it circles quiet roads
    forever: worth 0, the DFA never moves).
    """

    target: np.ndarray
    length: np.ndarray
    path: tuple[tuple[tuple[int, int], ...], ...]
    free: int

    @property
    def count(self) -> int:
        return int(self.target.size)


def quiet_incidents(symbols: ObservationSymbols) -> np.ndarray:
    """bool [n_incidents]: one observation, of probability exactly 1, that leaves every belief as it is."""
    # symbols.identity: the filter returns the belief bit for bit and the probability is the
    # likelihood's constant (TrustPOMDP.belief_update), here exactly 1
    return np.array([len(members) == 1 and bool(symbols.identity[members[0]])
                     and bool(symbols.likelihood[members[0], 0] == 1.0)
                     for members in symbols.by_incident], dtype=bool)


class EventGraph:
    """Macro moves per product context (x, q, p), computed on first use and cached."""

    def __init__(self, tables: ProductTables, symbols: ObservationSymbols, task: StateOnlyTask,
                 chains_only: bool = False, free_slot: np.ndarray | None = None) -> None:
        self.tables, self.task = tables, task
        successors = tables.successors
        self.successors = successors
        quiet_road = quiet_incidents(symbols)[np.asarray(tables.pomdp.road_incident)]      # [n_x]
        self.chains_only = chains_only
        if chains_only:
            # Only quiet roads without a choice (one junction) are passed through: a macro move is
            # then a junction followed down its chain, so there are no more moves than junctions.
            quiet_road &= (successors >= 0).sum(axis=1) == 1
        # q_moves[q, x]: some letter of road x moves q; p_moves[p, x]: the task state moves on x
        q_moves = (tables.next_q != np.arange(tables.n_q)[:, None, None]).any(axis=2)
        next_p = np.asarray(task.next_state, dtype=np.int64)
        p_moves = next_p != np.arange(next_p.shape[0])[:, None]
        self.quiet_road, self.q_moves, self.p_moves = quiet_road, q_moves, p_moves
        # the free completion's move per (road, DFA state, task state) (routing/free.py,
        # FreeCompletion.slot; default: the state-only task's, the first move where it has none)
        if free_slot is None:
            free_slot = np.broadcast_to(np.where(task.next_slot >= 0, task.next_slot, 0)[:, None, :],
                                        (tables.n_x, tables.n_q, task.next_slot.shape[1]))
        self.free_slot = free_slot
        live = ~(tables.accepting | tables.rejecting)
        # roads quiet for some live DFA state and some task state, and roads that are events for some
        self.maybe_quiet = quiet_road & (~q_moves[live]).any(axis=0) & (~p_moves).any(axis=0)
        self.maybe_event = ~quiet_road | q_moves[live].any(axis=0) | p_moves.any(axis=0)
        #: False: no road is quiet for any live (q, p); the moves are then the town's junctions.
        self.compresses = bool(self.maybe_quiet.any())
        self._cache: dict[tuple[int, int, int], MacroMoves] = {}
        self.width = self._width_bound()
        # table(): per context (x, q, p) a row of the padded move arrays, built on first use
        self._row = np.full((tables.n_x, tables.n_q, next_p.shape[0]), -1, dtype=np.int64)
        self._target = np.zeros((0, self.width), dtype=np.int64)
        self._length = np.zeros((0, self.width), dtype=np.int64)
        self._legal = np.zeros((0, self.width), dtype=bool)
        self._free = np.zeros(0, dtype=np.int64)

    def event_roads(self, q: int, p: int) -> np.ndarray:
        """bool [n_x]: the event roads of DFA state q and task state p (module docstring)."""
        return ~self.quiet_road | self.q_moves[q] | self.p_moves[p]

    def _width_bound(self) -> int:
        """Most macro moves of any context: per road, the roads reachable through roads that are
        quiet for some (q, p), counting those that are events for some (q, p); plus the free move.
        Chains only: one move per junction."""
        if not self.compresses or self.chains_only:
            return int(self.successors.shape[1])
        widest = 1
        for x in range(self.successors.shape[0]):
            seen = self._reach(x, self.maybe_quiet)
            widest = max(widest, int(self.maybe_event[list(seen)].sum()) if seen else 0)
        return widest + 1

    def _reach(self, x: int, passable: np.ndarray) -> set[int]:
        """Roads reachable from x in one or more junctions through `passable` roads (the last road
        need not be passable)."""
        seen: set[int] = set()
        queue = deque([x])
        while queue:
            road = queue.popleft()
            for s in self.successors[road]:
                s = int(s)
                if s < 0 or s in seen:
                    continue
                seen.add(s)
                if passable[s]:
                    queue.append(s)
        return seen

    def moves(self, x: int, q: int, p: int) -> MacroMoves:
        key = (x, q, p)
        cached = self._cache.get(key)
        if cached is None:
            cached = self._build(x, q, p)
            self._cache[key] = cached
        return cached

    def _build(self, x: int, q: int, p: int) -> MacroMoves:
        event = self.event_roads(q, p)
        successors = self.successors
        if self.chains_only:
            # one move per junction, down its chain (the free move is the free junction's)
            chains = [self._walk(x, slot, event, lambda road: 0)
                      for slot in range(int((successors[x] >= 0).sum()))]
            return MacroMoves(target=np.array([e for e, _ in chains], dtype=np.int64),
                              length=np.array([len(route) for _, route in chains], dtype=np.int64),
                              path=tuple(route for _, route in chains),
                              free=int(self.free_slot[x, q, p]))
        # Breadth-first over quiet roads from x, successors in slot order: each road is reached
        # first by a shortest path (in junctions), recorded by its predecessor and slot.
        parent: dict[int, tuple[int, int]] = {}
        order: list[int] = []           # event roads in the order found
        queue = deque([x])
        while queue:
            road = queue.popleft()
            for slot, s in enumerate(successors[road].tolist()):
                if s < 0 or s in parent:
                    continue
                parent[s] = (road, slot)
                if event[s]:
                    order.append(s)
                else:
                    queue.append(s)
        paths = [self._path_to(e, x, parent) for e in order]
        # Ordered by the first junction (then length, then road): with no quiet road these are the
        # town's junctions in slot order, so the search is the plain one.
        ranked = sorted(range(len(order)), key=lambda i: (paths[i][0][1], len(paths[i]), order[i]))
        target = [order[i] for i in ranked]
        path = [paths[i] for i in ranked]
        free_target, free_path = self._free_path(x, q, p, event)
        free = next((a for a, (e, route) in enumerate(zip(target, path, strict=True))
                     if e == free_target and len(route) == len(free_path)), -1)
        if free < 0:
            free = len(target)
            target.append(free_target)
            path.append(free_path)
        return MacroMoves(target=np.array(target, dtype=np.int64),
                          length=np.array([len(route) for route in path], dtype=np.int64),
                          path=tuple(path), free=free)

    @staticmethod
    def _path_to(e: int, x: int, parent: dict[int, tuple[int, int]]) -> tuple[tuple[int, int], ...]:
        steps = []
        road = e
        while True:
            before, slot = parent[road]
            steps.append((before, slot))
            if before == x:     # the walk's start (x may also be a target, back on a cycle)
                break
            road = before
        return tuple(reversed(steps))

    def _free_path(self, x: int, q: int, p: int, event: np.ndarray
                   ) -> tuple[int, tuple[tuple[int, int], ...]]:
        """(target, path) of the free completion from (x, q, p) to its first event road; target -1
        when it circles quiet roads forever (neither q nor p moves on quiet roads, so its moves
        repeat)."""
        return self._walk(x, int(self.free_slot[x, q, p]), event,
                          lambda road: int(self.free_slot[road, q, p]))

    def _walk(self, x: int, first: int, event: np.ndarray, slot_at: Callable[[int], int]
              ) -> tuple[int, tuple[tuple[int, int], ...]]:
        """(target, path) of the walk from x taking junction `first`, then slot_at(road) on each
        quiet road, to the first event road; target -1 when it circles quiet roads forever."""
        steps = []
        road, seen, slot = x, set(), first
        while True:
            steps.append((road, slot))
            nxt = int(self.successors[road, slot])
            if event[nxt]:
                return nxt, tuple(steps)
            if nxt in seen:
                return -1, tuple(steps)
            seen.add(nxt)
            road = nxt
            slot = slot_at(road)

    def table(self, x: np.ndarray, q: np.ndarray, p: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(target, length, legal) [m, width] and free [m] for contexts (x, q, p). Unused slots are
        not legal; a legal slot with target -1 is a move that never reaches an event road."""
        row = self._row[x, q, p]
        missing = row < 0
        if missing.any():
            contexts = np.unique(np.stack([x[missing], q[missing], p[missing]], axis=1), axis=0)
            built = [self.moves(xi, qi, pi) for xi, qi, pi in contexts.tolist()]
            target = np.full((len(built), self.width), -1, dtype=np.int64)
            length = np.zeros((len(built), self.width), dtype=np.int64)
            legal = np.zeros((len(built), self.width), dtype=bool)
            for k, moves in enumerate(built):
                target[k, : moves.count] = moves.target
                length[k, : moves.count] = moves.length
                legal[k, : moves.count] = True
            first = self._free.size
            self._row[contexts[:, 0], contexts[:, 1], contexts[:, 2]] = first + np.arange(len(built))
            self._target = np.concatenate([self._target, target])
            self._length = np.concatenate([self._length, length])
            self._legal = np.concatenate([self._legal, legal])
            self._free = np.concatenate([self._free, [moves.free for moves in built]])
            row = self._row[x, q, p]
        return self._target[row], self._length[row], self._legal[row], self._free[row]
