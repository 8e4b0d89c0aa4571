"""The node store of the belief-MDP search: growable arrays of the unfolded product belief MDP.

One node per distinct (junctions t, road x, DFA state q, state-only task state p, belief bytes,
exact belief): identical beliefs at the same depth are merged, never approximated. A node keeps the
word of the first history that reached it (policies/belief/exact_labels.py: its labels at
thresholds are decided exactly on that word's belief), and a history of another word joins it only
when both words lead to one exact belief (`same_belief`); one of another exact belief, whose float
belief happens to be the same, gets a node of its own. So every label at every node is the one the
vehicle reads on any history that reaches the node. Per node: its kind (below), its bounds [L, U] and
strict value, its completion bounds, and, once expanded, its move slots with their children and
probabilities.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

# FRONTIER: open, L = 0 (the policy drives the trust-free completion there, worth >= 0).
# FREE: expanded along the trust-free completion's move only; L is that move's exact value, U the
# abstraction's bound (the other moves are unexplored). EXPANDED: every move; a policy row.
FRONTIER, EXPANDED, ACCEPTED, ZERO, FREE = 0, 1, 2, 3, 4


class BeliefGraph:
    """Growable node arrays of the unfolded product belief MDP."""

    def __init__(self, n_trust: int, n_actions: int, n_outcomes: int,
                 same_belief: Callable[[int, int], bool]) -> None:
        """same_belief(word, word): whether two words lead to one exact belief (ExactFilter)."""
        self.n = 0
        self.same_belief = same_belief
        self.n_actions, self.n_outcomes = n_actions, n_outcomes
        capacity = 1024
        self.level = np.zeros(capacity, dtype=np.int64)
        self.x = np.zeros(capacity, dtype=np.int64)
        self.q = np.zeros(capacity, dtype=np.int64)
        self.p = np.zeros(capacity, dtype=np.int64)      # state of the state-only task (free route)
        self.cell = np.zeros(capacity, dtype=np.int64)
        self.belief = np.zeros((capacity, n_trust))
        self.word = np.zeros(capacity, dtype=np.int64)
        # U, L and the strict value as rows of one array, so that a backup gathers all three at once
        self.values = np.zeros((3, capacity))
        self.upper, self.lower = self.values[0], self.values[1]
        # value of the L-greedy choice with every label read as the vehicle reads it: the
        # tie-breaker among actions of equal L, and a reported figure.
        self.strict = self.values[2]
        self.kind = np.zeros(capacity, dtype=np.int8)
        # Bounds on the trust-free completion's value from the node (completion_value.py): its
        # lower bound is the L of a FRONTIER node; its upper bound decides where the policy may
        # leave the free move (BeliefSearch.choose, expansion.py). free_upper starts at the
        # abstraction's bound.
        self.free_upper = np.zeros(capacity)
        self.free_lower = np.zeros(capacity)
        self.completed = np.zeros(capacity, dtype=bool)
        # per expanded node: which move slots exist, and the trust-free completion's slot
        self.legal = np.zeros((capacity, n_actions), dtype=bool)
        self.free_move = np.zeros(capacity, dtype=np.int64)
        self.child = np.full((capacity, n_actions, n_outcomes), -1, dtype=np.int64)
        self.prob = np.zeros((capacity, n_actions, n_outcomes))
        # per level: (x, q, p, belief bytes) -> (node, word), or a list of them, one per exact belief
        self.memo: list[dict[tuple[int, int, int, bytes], tuple[int, int] | list[tuple[int, int]]]] = []
        self.expanded_by_level: list[list[int]] = []
        self.free_by_level: list[dict[int, None]] = []    # FREE nodes per level (insertion order)
        self.free_version: list[int] = []

    def _grow(self, needed: int) -> None:
        capacity = self.level.shape[0]
        if needed <= capacity:
            return
        new = max(needed, 2 * capacity)
        for name in ("level", "x", "q", "p", "cell", "kind", "free_move", "free_upper", "free_lower",
                     "completed", "word"):
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
            cell: np.ndarray, belief: np.ndarray, word: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ids of the nodes (level, x, q, p, belief, the exact belief of `word`), creating missing
        ones; and a mask of new ones. word: of the history that reaches each (module docstring)."""
        level = np.broadcast_to(np.asarray(level, dtype=np.int64), x.shape)
        deepest = int(level.max()) if level.size else 0
        while len(self.memo) <= deepest:
            self.memo.append({})
            self.expanded_by_level.append([])
            self.free_by_level.append({})
            self.free_version.append(0)
        ids = np.empty(x.size, dtype=np.int64)
        new = np.zeros(x.size, dtype=bool)
        start = self.n
        self._grow(self.n + x.size)
        memos = self.memo
        for i, (lv, w, *key) in enumerate(zip(level.tolist(), word.tolist(), x.tolist(), q.tolist(),
                                              p.tolist(), (row.tobytes() for row in belief), strict=True)):
            memo, k = memos[lv], tuple(key)
            found = memo.get(k)
            if isinstance(found, tuple) and found[1] == w:
                ids[i] = found[0]         # (the usual case: one word per float belief)
                continue
            node = None if found is None else self._same(found, w)
            if node is None:
                node = self.n
                self.n += 1
                new[i] = True
                memo[k] = (node, w) if found is None else [*_entries(found), (node, w)]
            ids[i] = node
        created = ids[new]
        self.level[created] = level[new]
        self.x[created] = x[new]
        self.q[created] = q[new]
        self.p[created] = p[new]
        self.cell[created] = cell[new]
        self.belief[created] = belief[new]
        self.word[created] = word[new]
        self.kind[created] = FRONTIER
        self.completed[created] = False
        self.free_lower[created] = 0.0
        assert self.n == start + created.size
        return ids, new

    def _same(self, found: tuple[int, int] | list[tuple[int, int]], word: int) -> int | None:
        """The node among `found` whose word leads to the exact belief of `word`, if any."""
        for node, other in _entries(found):
            if self.same_belief(other, word):
                return node
        return None


def _entries(found: tuple[int, int] | list[tuple[int, int]]) -> list[tuple[int, int]]:
    return [found] if isinstance(found, tuple) else found


@dataclass(frozen=True, eq=False)
class ExpandedLevel:
    """The expanded nodes of one level with their (fixed) children, for the backups.

    nodes [m]; child [m, actions, outcomes] (0 where absent, masked by has_child); prob; legal
    [m, actions]."""

    count: int
    nodes: np.ndarray
    child: np.ndarray
    has_child: np.ndarray
    prob: np.ndarray
    legal: np.ndarray
