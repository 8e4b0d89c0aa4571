"""The synthesized policy of a spec with trust-state atoms: decisions over (junctions, road, joint belief).

With trust-state atoms the DFA state is hidden, so the policy acts on the exact joint belief J(θ, q)
that the AV tracks online (policies/belief/trust_state_filter.py; the episode tracker and the exact
evaluation pass it in `DecisionContext.joint`). Rows are the nodes the trust-state search expanded
(policies/trust_state_synthesis/search.py): t (junctions driven), road x, the DFA state told (most
probable under J), the AV belief b, J, and the action slot chosen there. The rule for any context
(docs/formats/policy_file.md, "Joint policies"):

1. among rows with the same (t, x), the row nearest to (J, b) (Euclidean, J flattened); its action
   if that distance is at most MATCH_TOLERANCE (a node the search expanded, up to rounding);
2. otherwise the successor with the largest relaxed action value at J
   (policies/belief/trust_state_relaxation.py, RelaxedGuide; k = guide_horizon - t - 1 junctions
   left, the full guide horizon once t reaches it).

`reweight` (a policy made for a driver population under another type prior λ than the weights w
of the AV's filter, policies/trust_state_synthesis/population.py): before both rules, J and b are
reweighted by r = λ_k / w_k on type k's block of the hidden (type, trust) index and renormalised
(a row with no mass left stays as it was), the posterior under prior λ of the same observations
(docs/driver_types.md, "The robust objective").

The policy's certified lower bound is its own exact value (policies/trust_state_synthesis/synthesis.py
evaluates it), so the rule off the stored nodes needs no optimality claim.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from trustroute.networks.town import Town
from trustroute.policies.belief.trust_state_relaxation import RelaxedGuide, relaxed_guide
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import TrustPOMDP
from trustroute.policies.routing.aware_table import store_row_arrays
from trustroute.policies.routing.protocol import UNCERTIFIED, Certificate, DecisionContext, RoutingPolicy

MATCH_TOLERANCE = 1e-9


@dataclass(frozen=True, eq=False)
class JointPolicyTable:
    """Decision rows; t, x, q, action [rows], beliefs [rows, n_trust], joint [rows, n_trust, n_q]."""

    t: np.ndarray
    x: np.ndarray
    q: np.ndarray
    beliefs: np.ndarray
    joint: np.ndarray
    action: np.ndarray

    def __post_init__(self) -> None:
        store_row_arrays(self, integers=("t", "x", "q", "action"), reals=("beliefs", "joint"))

    @property
    def rows(self) -> int:
        return int(self.t.size)

    def points(self) -> np.ndarray:
        """[rows, n_trust * n_q + n_trust]: the (J, b) each row is matched on."""
        return np.concatenate([self.joint.reshape(self.rows, int(np.prod(self.joint.shape[1:]))),
                               self.beliefs], axis=1)


class JointTablePolicy(RoutingPolicy):
    """RoutingPolicy "aware" for specs with trust-state atoms: reads `context.joint`."""

    def __init__(self, table: JointPolicyTable, pomdp: TrustPOMDP, spec: Spec, guide_horizon: int | None,
                 name: str = "aware", certificate: Certificate = UNCERTIFIED,
                 guide: RelaxedGuide | None = None, reweight: np.ndarray | None = None) -> None:
        self.table = table
        self.reweight = None if reweight is None else np.asarray(reweight, dtype=float)
        self.lower, self.upper, self.horizon = certificate.lower, certificate.upper, certificate.horizon
        self.pomdp = pomdp
        self.town: Town = pomdp.town
        self.spec = spec
        self.name = name
        self.guide_horizon = guide_horizon
        if guide is not None and guide.horizon != guide_horizon:
            raise ValueError(f"guide of horizon {guide.horizon}, policy of guide horizon {guide_horizon}")
        self._guide: RelaxedGuide | None = guide      # None: built from the spec on first use
        self._points = table.points()
        n_x = len(self.town.states)
        keys = table.t * n_x + table.x
        self._n_x = n_x
        self._groups: dict[int, np.ndarray] = {}
        self._trees: dict[int, cKDTree] = {}
        self._prefetched: dict[tuple[int, int, bytes, bytes], int] = {}
        if table.rows:
            order = np.argsort(keys, kind="stable")
            unique, first = np.unique(keys[order], return_index=True)
            for key, rows in zip(unique.tolist(), np.split(order, first[1:]), strict=True):
                self._groups[key] = rows

    @property
    def guide(self) -> RelaxedGuide:
        if self._guide is None:          # built on first use: most decisions hit stored rows
            self._guide = relaxed_guide(self.pomdp, self.spec, self.guide_horizon)
        return self._guide

    def _tree(self, key: int) -> cKDTree | None:
        tree = self._trees.get(key)
        if tree is None and key in self._groups:
            tree = self._trees[key] = cKDTree(self._points[self._groups[key]])
        return tree

    def stored_actions(self, t: int, x: np.ndarray, joint: np.ndarray, beliefs: np.ndarray) -> np.ndarray:
        """Rule 1 at n nodes of t junctions driven (roads x [n], joint [n, n_trust, n_q], beliefs
        [n, n_trust]): the stored action slot, -1 where no row matches."""
        x = np.asarray(x, dtype=np.int64)
        points = np.concatenate([np.asarray(joint, dtype=float).reshape(x.size, -1),
                                 np.asarray(beliefs, dtype=float).reshape(x.size, -1)], axis=1)
        if points.shape[1] != self._points.shape[1]:
            raise ValueError(f"joint belief and belief of {points.shape[1]} entries, the policy's rows "
                             f"have {self._points.shape[1]}")
        out = np.full(x.size, -1, dtype=np.int64)
        keys = t * self._n_x + x
        for key in np.unique(keys).tolist():
            tree = self._tree(key)
            if tree is None:
                continue
            members = np.flatnonzero(keys == key)
            distance, nearest = tree.query(points[members], distance_upper_bound=MATCH_TOLERANCE)
            found = np.isfinite(distance)
            rows = self._groups[key]
            out[members[found]] = self.table.action[rows[nearest[found]]]
        return out

    def action_slots(self, t: int, x: np.ndarray, joint: np.ndarray, beliefs: np.ndarray) -> np.ndarray:
        """The acting rule at n nodes of t junctions driven: int [n] action slots."""
        x = np.asarray(x, dtype=np.int64)
        joint = np.asarray(joint, dtype=float).reshape(x.size, self.pomdp.n_trust, -1)
        if self.reweight is not None:
            joint, beliefs = self.reweighted(joint, np.asarray(beliefs, dtype=float).reshape(x.size, -1))
        slots = self.stored_actions(t, x, joint, beliefs)
        rest = np.flatnonzero(slots < 0)
        if rest.size:
            slots[rest] = self.guide.policy_slots(t, x[rest], joint[rest])
        return slots

    def reweighted(self, joint: np.ndarray, beliefs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """J [n, n_trust, n_q] and b [n, n_trust] under the policy's type prior (module docstring)."""
        r = self.reweight
        assert r is not None

        def normalised(weighted: np.ndarray, original: np.ndarray) -> np.ndarray:
            total = weighted.reshape(weighted.shape[0], -1).sum(axis=1)
            total = total.reshape((-1,) + (1,) * (weighted.ndim - 1))
            return np.where(total > 0, weighted / np.where(total > 0, total, 1.0), original)

        return (normalised(joint * r[None, :, None], joint), normalised(beliefs * r[None, :], beliefs))

    def route_memory(self, route: tuple[str, ...]) -> tuple:
        """Nothing: the decision is a function of (junctions driven, road, J, AV belief)."""
        return ()

    def certified_bounds(self) -> tuple[float, float] | None:
        if self.lower is None or self.upper is None:
            return None
        return float(self.lower), float(self.upper)

    def prefetch(self, t: int, x: np.ndarray, joint: np.ndarray, beliefs: np.ndarray) -> None:
        """Decide n nodes of t junctions driven in one vectorised `action_slots` call, for the
        `next_junction` calls that follow (an evaluator asks node by node through the episode
        rules, where one call per node costs most of its time); replaces the last batch."""
        x = np.asarray(x, dtype=np.int64)
        joint = np.asarray(joint, dtype=float)
        beliefs = np.asarray(beliefs, dtype=float)
        slots = self.action_slots(t, x, joint, beliefs)
        self._prefetched = {(t, xi, j.tobytes(), b.tobytes()): s for xi, j, b, s in
                            zip(x.tolist(), joint, beliefs, slots.tolist(), strict=True)}

    def forget_prefetched(self) -> None:
        self._prefetched = {}

    def next_junction(self, context: DecisionContext) -> str:
        if context.joint is None:
            raise ValueError(f"policy {self.name!r} of spec {self.spec.name!r} acts on the joint "
                             "belief over (trust, DFA state); the caller passed none")
        x = self.town.state_index(context.road)
        slot = self._prefetched.get((context.junctions_driven, x,
                                     np.asarray(context.joint, dtype=float).tobytes(),
                                     np.asarray(context.belief, dtype=float).tobytes()))
        if slot is None:
            slot = int(self.action_slots(context.junctions_driven, np.array([x]), context.joint[None],
                                         np.asarray(context.belief)[None])[0])
        return self.town.actions(context.road)[slot]
