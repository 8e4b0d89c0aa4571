"""The synthesized ("aware") routing policy: a table of decisions over (junctions, road, DFA state, belief).

Rows are the product nodes the synthesis expanded: t (junctions driven), road x, DFA state q,
belief b and the action slot (index into town.actions(road)) chosen there. The rule for any
DecisionContext (documented, and the same on every belief, visited or not):

1. among rows with the same (t, x, q), take the row whose belief is nearest (Euclidean);
2. if there is none, among rows with the same (x, q) at any t, the nearest belief;
3. if there is none, drive the trust-free shortest completion of the state-only task
   (policies.baseline), or the first legal move when that task is complete or impossible.

Beliefs the synthesis visited are stored exactly, so on them the policy takes exactly the
decision whose value the synthesis certified.

`reweight` (a policy made for a driver population with another type prior λ than the
population's weights w, docs/driver_types.md "The robust objective"): the belief the policy is given
(the type-aware filter under w) is first turned into the belief under λ, b_λ ∝ b_w · r with
r = λ_k / w_k on type k's block (exact: the likelihood of the observations given the type does not
depend on the prior). Without it nothing changes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from trustroute.networks.town import Town
from trustroute.policies.logic.spec import Spec
from trustroute.policies.routing.free import state_only_task
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy


@dataclass(frozen=True, eq=False)
class PolicyTable:
    """Decision rows; all arrays have one entry per row (beliefs: [rows, n_trust])."""

    t: np.ndarray
    x: np.ndarray
    q: np.ndarray
    beliefs: np.ndarray
    action: np.ndarray

    def __post_init__(self) -> None:
        for name in ("t", "x", "q", "action"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=np.int64))
        object.__setattr__(self, "beliefs", np.asarray(self.beliefs, dtype=float))

    @property
    def rows(self) -> int:
        return int(self.t.size)


BRUTE_FORCE_PAIRS = 256   # queries x stored rows below which nearest rows are found by a scan


@dataclass(frozen=True, eq=False)
class _Groups:
    """Rows grouped by an integer key; per group its rows and (when it has several) a k-d tree."""

    rows: dict[int, np.ndarray]
    trees: dict[int, cKDTree]
    beliefs: np.ndarray

    def nearest(self, key: int, beliefs: np.ndarray) -> np.ndarray | None:
        """Row index of the nearest stored belief for each of `beliefs` [m, n] (None: no group)."""
        rows = self.rows.get(key)
        if rows is None:
            return None
        if rows.size == 1:
            return np.repeat(rows, beliefs.shape[0])
        if rows.size * beliefs.shape[0] <= BRUTE_FORCE_PAIRS:
            # Small groups: a direct distance scan beats the tree's per-query overhead.
            stored = self.beliefs[rows]
            distance = ((beliefs[:, None, :] - stored[None, :, :]) ** 2).sum(axis=2)
            return rows[distance.argmin(axis=1)]
        _, nearest = self.trees[key].query(beliefs)
        return rows[np.asarray(nearest)]


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


class BeliefTablePolicy(RoutingPolicy):
    """RoutingPolicy "aware": nearest stored belief at the same (junctions, road, DFA state)."""

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
        self._n_q = int(table.q.max()) + 1 if table.rows else 1
        self._exact = _group(self._key_tq(table.t, table.x, table.q), table.beliefs)
        self._any_t = _group(self._key_q(table.x, table.q), table.beliefs)

    def _key_q(self, x: np.ndarray, q: np.ndarray) -> np.ndarray:
        return x * self._n_q + q

    def _key_tq(self, t: np.ndarray, x: np.ndarray, q: np.ndarray) -> np.ndarray:
        return (t * self._n_x + x) * self._n_q + q

    def action_slots(self, t: np.ndarray, x: np.ndarray, q: np.ndarray, beliefs: np.ndarray) -> np.ndarray:
        """Vectorised rule 1-2: action slot per row, -1 where no stored row matches (rule 3)."""
        t, x, q = (np.atleast_1d(np.asarray(a, dtype=np.int64)) for a in (t, x, q))
        beliefs = np.atleast_2d(np.asarray(beliefs, dtype=float))
        if self.reweight is not None:
            weighted = beliefs * self.reweight
            total = weighted.sum(axis=1, keepdims=True)
            beliefs = np.where(total > 0, weighted / np.where(total > 0, total, 1.0), beliefs)
        out = np.full(t.size, -1, dtype=np.int64)
        if t.size == 0 or not self.table.rows:
            return out
        known_q = q < self._n_q             # a DFA state never stored has no row anywhere
        for keys, groups in ((self._key_tq(t, x, q), self._exact), (self._key_q(x, q), self._any_t)):
            todo = np.flatnonzero((out < 0) & known_q)
            if todo.size == 0:
                break
            if todo.size == 1:
                i = int(todo[0])
                rows = groups.nearest(int(keys[i]), beliefs[i:i + 1])
                if rows is not None:
                    out[i] = self.table.action[rows[0]]
                continue
            unique, inverse = np.unique(keys[todo], return_inverse=True)
            for g, key in enumerate(unique.tolist()):
                members = todo[inverse == g]
                rows = groups.nearest(key, beliefs[members])
                if rows is not None:
                    out[members] = self.table.action[rows]
        return out

    def certified_bounds(self) -> tuple[float, float] | None:
        if self.lower is None or self.upper is None:
            return None
        return float(self.lower), float(self.upper)

    def next_junction(self, context: DecisionContext) -> str:
        road = context.road
        x = self.town.state_index(road)
        slot = int(self.action_slots(np.array([context.junctions_driven]), np.array([x]),
                                     np.array([context.dfa_state]), context.belief)[0])
        actions = self.town.actions(road)
        if 0 <= slot < len(actions):
            return actions[slot]
        junction = self.task.next_junction(road, self.task.projected_state(context.route))
        return junction if junction is not None else actions[0]
