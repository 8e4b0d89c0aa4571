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


def _group(keys: np.ndarray, beliefs: np.ndarray) -> dict[tuple[int, ...], tuple[cKDTree, np.ndarray]]:
    out: dict[tuple[int, ...], tuple[cKDTree, np.ndarray]] = {}
    if keys.shape[0] == 0:
        return out
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    order = np.argsort(inverse, kind="stable")
    bounds = np.searchsorted(inverse[order], np.arange(unique.shape[0] + 1))
    for g in range(unique.shape[0]):
        rows = order[bounds[g]:bounds[g + 1]]
        out[tuple(int(v) for v in unique[g])] = (cKDTree(beliefs[rows]), rows)
    return out


class BeliefTablePolicy(RoutingPolicy):
    """RoutingPolicy "aware": nearest stored belief at the same (junctions, road, DFA state)."""

    def __init__(self, table: PolicyTable, town: Town, spec: Spec, name: str = "aware",
                 lower: float | None = None, upper: float | None = None,
                 horizon: int | None = None) -> None:
        self.table = table
        self.lower, self.upper, self.horizon = lower, upper, horizon   # as certified by synthesis
        self.town = town
        self.spec = spec
        self.name = name
        self.task = state_only_task(town, spec)
        self._exact = _group(np.stack([table.t, table.x, table.q], axis=1), table.beliefs)
        self._any_t = _group(np.stack([table.x, table.q], axis=1), table.beliefs)

    def action_slots(self, t: np.ndarray, x: np.ndarray, q: np.ndarray, beliefs: np.ndarray) -> np.ndarray:
        """Vectorised rule 1-2: action slot per row, -1 where no stored row matches (rule 3)."""
        t, x, q = (np.asarray(a, dtype=np.int64) for a in (t, x, q))
        beliefs = np.atleast_2d(np.asarray(beliefs, dtype=float))
        out = np.full(t.size, -1, dtype=np.int64)
        if t.size == 0:
            return out
        for keys, groups in ((np.stack([t, x, q], axis=1), self._exact),
                             (np.stack([x, q], axis=1), self._any_t)):
            todo = np.flatnonzero(out < 0)
            if todo.size == 0:
                break
            unique, inverse = np.unique(keys[todo], axis=0, return_inverse=True)
            inverse = inverse.ravel()
            for g in range(unique.shape[0]):
                entry = groups.get(tuple(int(v) for v in unique[g]))
                if entry is None:
                    continue
                tree, rows = entry
                members = todo[inverse == g]
                _, nearest = tree.query(beliefs[members])
                out[members] = self.table.action[rows[np.asarray(nearest)]]
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
