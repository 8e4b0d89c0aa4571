"""The synthesized ("aware") routing policy: a table of decisions over (junctions, road, DFA state, belief).

Rows are the product nodes the synthesis expanded: t (junctions driven), road x, DFA state q,
belief b, the action slot (index into town.actions(road)) chosen there and p, the state of the
spec's state-only task (policies/routing/free.py) after the roads driven. The acting rule
(docs/synthesis.md, "Open nodes and the acting rule"): at a context (t, x, q, p, b), the row with
the same (t, x, q, p) whose belief is within EXACT_BELIEF_DISTANCE of b; if there is none, among
the box rows of (t, x, q) (a cluster policy's, docs/synthesis.md "Cluster policies") whose box
holds b, the one of the largest certified value; if there is none, the move of the free
completion at (x, q, p) (policies/routing/free.py, `free_completion`): the trust-free shortest
completion of the state-only task while it is not complete, after it the shortest route back to
what the DFA still needs, every label allowed (so a waypoint reached with too little trust is
visited again). The synthesis values every node without a row by exactly this completion, so
the policy's value is the synthesised L (docs/synthesis.md, "Open nodes and the acting rule").
The table kinds and their files: policies/routing/decision_tables.py.

`reweight` (a policy made for a driver population with another type prior λ than the
population's weights w, docs/driver_types.md "The robust objective"): the belief the policy is given
(the type-aware filter under w) is first turned into the belief under λ, b_λ ∝ b_w · r with
r = λ_k / w_k on type k's block (exact: the likelihood of the observations given the type does not
depend on the prior). Without it nothing changes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar, cast

import numpy as np
from scipy.spatial import cKDTree

from trustroute.networks.town import Town
from trustroute.policies.logic.spec import Spec
from trustroute.policies.routing.free import free_completion, state_only_task
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy


def store_row_arrays(rows, integers: tuple[str, ...], reals: tuple[str, ...]) -> None:
    """Hold a frozen table's row fields as numpy arrays: `integers` as int64, `reals` as float."""
    for names, dtype in ((integers, np.int64), (reals, float)):
        for name in names:
            object.__setattr__(rows, name, np.asarray(getattr(rows, name), dtype=dtype))


@dataclass(frozen=True, eq=False)
class BoxRows:
    """Box rows (policies/synthesis/cluster_policy.py): at (t, x, q), a belief inside [lo, hi] may
    take `action`, worth at least `value` from every belief of the box; among the boxes holding a
    belief the one of the largest value acts."""

    t: np.ndarray
    x: np.ndarray
    q: np.ndarray
    lo: np.ndarray        # [rows, n_trust]
    hi: np.ndarray
    value: np.ndarray
    action: np.ndarray

    def __post_init__(self) -> None:
        store_row_arrays(self, integers=("t", "x", "q", "action"), reals=("lo", "hi", "value"))

    @property
    def rows(self) -> int:
        return int(self.t.size)

    def take(self, index: np.ndarray) -> BoxRows:
        """The rows at `index`, in that order."""
        return BoxRows(t=self.t[index], x=self.x[index], q=self.q[index], lo=self.lo[index],
                       hi=self.hi[index], value=self.value[index], action=self.action[index])

    @staticmethod
    def empty(n_trust: int) -> BoxRows:
        none = np.zeros(0, dtype=np.int64)
        return BoxRows(t=none, x=none, q=none, lo=np.zeros((0, n_trust)), hi=np.zeros((0, n_trust)),
                       value=np.zeros(0), action=none)


@dataclass(frozen=True, eq=False)
class PolicyTable:
    """Exact rows; all arrays have one entry per row (beliefs: [rows, n_trust]). boxes: the box
    rows of a cluster policy (None: none)."""

    t: np.ndarray
    x: np.ndarray
    q: np.ndarray
    beliefs: np.ndarray
    action: np.ndarray
    projected: np.ndarray                  # state-only task state p per row
    boxes: BoxRows | None = None

    def __post_init__(self) -> None:
        store_row_arrays(self, integers=("t", "x", "q", "action", "projected"), reals=("beliefs",))

    @classmethod
    def empty(cls, n_trust: int, boxes: BoxRows | None = None) -> PolicyTable:
        """A table without exact rows (with `boxes`: a cluster policy's)."""
        return cls(t=np.zeros(0, dtype=np.int64), x=np.zeros(0, dtype=np.int64),
                   q=np.zeros(0, dtype=np.int64), beliefs=np.zeros((0, n_trust)),
                   action=np.zeros(0, dtype=np.int64), projected=np.zeros(0, dtype=np.int64),
                   boxes=boxes)

    @property
    def rows(self) -> int:
        return int(self.t.size)


BRUTE_FORCE_PAIRS = 256   # queries x stored rows below which nearest rows are found by a scan
# A belief this close (Euclidean) to a stored row's is that row's: the vehicle runs the same filter
# as the synthesis (docs/synthesis.md, "One filter"), so a visited belief matches to the last bit;
# the slack only absorbs a summation order that differs between batch shapes (a few ulps), far
# below the distance between distinct beliefs of one (t, road, DFA state).
EXACT_BELIEF_DISTANCE = 1e-12

# A context's key parts: one context (an episode's decision) or a batch of them.
KeyPart = TypeVar("KeyPart", int, np.ndarray)


@dataclass(frozen=True, eq=False)
class _Groups:
    """Rows grouped by an integer key; per group its rows and (when it has several) a k-d tree."""

    rows: dict[int, np.ndarray]
    trees: dict[int, cKDTree]
    beliefs: np.ndarray

    def nearest_with_distance(self, key: int, beliefs: np.ndarray
                              ) -> tuple[np.ndarray, np.ndarray] | None:
        """(row index, Euclidean distance) of the nearest stored belief for each of `beliefs`."""
        rows = self.rows.get(key)
        if rows is None:
            return None
        if rows.size * beliefs.shape[0] <= BRUTE_FORCE_PAIRS or rows.size == 1:
            # Small groups: a direct distance scan beats the tree's per-query overhead.
            stored = self.beliefs[rows]
            distance = ((beliefs[:, None, :] - stored[None, :, :]) ** 2).sum(axis=2)
            best = distance.argmin(axis=1)
            return rows[best], np.sqrt(distance[np.arange(beliefs.shape[0]), best])
        distance, nearest = self.trees[key].query(beliefs)
        return rows[np.asarray(nearest)], np.asarray(distance)


def _group(keys: np.ndarray, beliefs: np.ndarray) -> _Groups:
    rows: dict[int, np.ndarray] = {}
    trees: dict[int, cKDTree] = {}
    if keys.size:
        unique, inverse = np.unique(keys, return_inverse=True)
        order = np.argsort(inverse, kind="stable")
        bounds = np.searchsorted(inverse[order], np.arange(unique.size + 1))
        for g, key in enumerate(unique.tolist()):
            members = order[bounds[g]:bounds[g + 1]]
            rows[key] = members
            if members.size > 1:
                trees[key] = cKDTree(beliefs[members])
    return _Groups(rows=rows, trees=trees, beliefs=beliefs)


@dataclass(frozen=True, eq=False)
class _BoxIndex:
    """Box rows sorted by their (t, x, q) key, for the lookup of the boxes holding a belief."""

    keys: np.ndarray      # sorted keys, one per row
    rows: BoxRows         # in key order

    def slots(self, keys: np.ndarray, beliefs: np.ndarray) -> np.ndarray:
        """Per context: the action of the box of the largest value at its key holding its belief
        (-1: none holds it)."""
        out = np.full(keys.size, -1, dtype=np.int64)
        unique, inverse = np.unique(keys, return_inverse=True)
        first = np.searchsorted(self.keys, unique, side="left")
        last = np.searchsorted(self.keys, unique, side="right")
        for g in np.flatnonzero(last > first).tolist():
            members = np.flatnonzero(inverse == g)
            lo, hi = self.rows.lo[first[g]:last[g]], self.rows.hi[first[g]:last[g]]      # [k, n]
            held = beliefs[members]                                                       # [m, n]
            # [m, k]; all over an axis of a 3-d array is an array (the stubs allow a scalar)
            inside = cast(np.ndarray, ((lo[None] <= held[:, None]) & (held[:, None] <= hi[None])).all(axis=2))
            value = np.where(inside, self.rows.value[first[g]:last[g]][None, :], -np.inf)
            best = value.argmax(axis=1)
            found = inside[np.arange(members.size), best]
            out[members[found]] = self.rows.action[first[g] + best[found]]
        return out


class BeliefTablePolicy(RoutingPolicy):
    """RoutingPolicy "aware": the exact-belief rule over a PolicyTable (module docstring)."""

    def __init__(self, table: PolicyTable, town: Town, spec: Spec, name: str = "aware",
                 lower: float | None = None, upper: float | None = None,
                 horizon: int | None = None, reweight: np.ndarray | None = None) -> None:
        self.table = table
        self.reweight = None if reweight is None else np.asarray(reweight, dtype=float)
        self.lower, self.upper, self.horizon = lower, upper, horizon   # as certified by synthesis
        self.town = town
        self.spec = spec
        self.name = name
        self.task = state_only_task(town, spec)
        # Keys as single integers (road-major, then DFA state, then junctions) so that a lookup
        # is a dict access, not a row-wise unique.
        self._n_x = len(town.states)
        self._n_q = max(int(table.q.max()) + 1 if table.rows else 1,
                        int(table.boxes.q.max()) + 1 if table.boxes is not None and table.boxes.rows else 1)
        self._n_p = int(self.task.dfa.n_states)
        # the free completion's move per (road, DFA state, task state): the exact-belief rule's
        # fallback (module docstring)
        self._free_slot = free_completion(town, spec).slot
        self._boxes = None
        self._exact = _group(self._key_tqp(table.t, table.x, table.q, table.projected), table.beliefs)
        boxes = table.boxes
        if boxes is not None and boxes.rows:
            keys = self._key_tq(boxes.t, boxes.x, boxes.q)
            order = np.argsort(keys, kind="stable")
            self._boxes = _BoxIndex(keys=keys[order], rows=boxes.take(order))

    def _key_tq(self, t: KeyPart, x: KeyPart, q: KeyPart) -> KeyPart:
        return (t * self._n_x + x) * self._n_q + q

    def _policy_beliefs(self, beliefs: np.ndarray) -> np.ndarray:
        """The beliefs the table is looked up with: reweighted to the policy's type prior when it
        has one (module docstring)."""
        beliefs = np.atleast_2d(np.asarray(beliefs, dtype=float))
        if self.reweight is None:
            return beliefs
        weighted = beliefs * self.reweight
        total = weighted.sum(axis=1, keepdims=True)
        return np.where(total > 0, weighted / np.where(total > 0, total, 1.0), beliefs)

    def _key_tqp(self, t: KeyPart, x: KeyPart, q: KeyPart, p: KeyPart) -> KeyPart:
        return self._key_tq(t, x, q) * self._n_p + p

    def exact_action_slots(self, t: np.ndarray, x: np.ndarray, q: np.ndarray, projected: np.ndarray,
                           beliefs: np.ndarray) -> np.ndarray:
        """The exact-belief rule, vectorised: the slot per context (never -1)."""
        t, x, q, p = (np.atleast_1d(np.asarray(a, dtype=np.int64)) for a in (t, x, q, projected))
        beliefs = self._policy_beliefs(beliefs)
        out = self._free_slot[x, q, p].copy()
        if t.size == 0:
            return out
        exact = np.zeros(t.size, dtype=bool)
        if self.table.rows:
            keys = self._key_tqp(t, x, q, p)
            unique, inverse = np.unique(keys, return_inverse=True)
            for g, key in enumerate(unique.tolist()):
                members = np.flatnonzero(inverse == g)
                found = self._exact.nearest_with_distance(key, beliefs[members])
                if found is not None:
                    rows, distance = found
                    hit = distance <= EXACT_BELIEF_DISTANCE
                    out[members[hit]] = self.table.action[rows[hit]]
                    exact[members[hit]] = True
        if self._boxes is not None:
            todo = np.flatnonzero(~exact & (q < self._n_q))
            boxed = self._boxes.slots(self._key_tq(t[todo], x[todo], q[todo]), beliefs[todo])
            out[todo[boxed >= 0]] = boxed[boxed >= 0]
        return out

    def action_slots(self, t: np.ndarray, x: np.ndarray, q: np.ndarray, beliefs: np.ndarray,
                     projected: np.ndarray | None = None) -> np.ndarray:
        """Vectorised decisions: the action slot per context (never -1); `projected` is the
        state-only task state per context, which the rule reads."""
        if projected is None:
            raise ValueError("this policy's exact-belief rule needs the state-only task state "
                             "(projected) of each context")
        return self.exact_action_slots(t, x, q, projected, beliefs)

    def certified_bounds(self) -> tuple[float, float] | None:
        if self.lower is None or self.upper is None:
            return None
        return float(self.lower), float(self.upper)

    def _exact_slot(self, t: int, x: int, q: int, p: int, belief: np.ndarray) -> int:
        """`exact_action_slots` of one context (an episode's decision): one dict access and one
        nearest-row search, without the grouping of a batch (the same rows, so the same slot). Most
        contexts of a long evaluation lie past every row (the free completion acts there): those
        return before their belief is read."""
        slot = int(self._free_slot[x, q, p])
        key = self._key_tqp(t, x, q, p)
        boxes = self._boxes if q < self._n_q else None
        if key not in self._exact.rows and boxes is None:
            return slot
        beliefs = self._policy_beliefs(belief)
        found = self._exact.nearest_with_distance(key, beliefs)
        if found is not None and found[1][0] <= EXACT_BELIEF_DISTANCE:
            return int(self.table.action[found[0][0]])
        if boxes is not None:
            box_slot = int(boxes.slots(self._key_tq(np.array([t]), np.array([x]), np.array([q])),
                                       beliefs)[0])
            if box_slot >= 0:
                return box_slot
        return slot

    def next_junction(self, context: DecisionContext) -> str:
        road = context.road
        x = self.town.state_index(road)
        p = self.task.projected_state(context.route)
        slot = self._exact_slot(context.junctions_driven, x, int(context.dfa_state), p, context.belief)
        return self.town.actions(road)[slot]
