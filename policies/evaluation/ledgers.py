"""Where the mass of the episode tree goes: the ledgers of the unfolding, and the Evaluation.

The unfolding (policies/evaluation/unfolding.py) asks its ledger, level by level, which nodes end
(the DFA has decided, the junction cap), which are cut (too unlikely, beyond the level's budget,
out of time) and what an ending or a cut adds up to. Three readings:

- `PathLedger`: the DFA state is observed (ObservedState, masses 0 or 1): a node ends accepted or
  rejected whole; a cut node's whole mass is unknown. The exact evaluation of plain specs.
- `JointLedger`: any node state: a node's accepted and rejected masses count when it ends or is
  cut, its live mass goes to the end reason (unknown when cut), and the cuts are itemised
  (`pruning`). The evaluation of specs with trust-state atoms.
- `BoundLedger`: only [lower, upper] of P(accepted within the cap), for a policy without episode
  rules (JointTablePolicy): the synthesis's certified lower end.

Each keeps the summation order of the loop it serves, so its numbers are bit for bit the same.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from trustroute.policies.evaluation.node_state import ObservedState

DEFAULT_PRUNE_BELOW = 1e-12
DEFAULT_MAX_NODES = 2_000_000


@dataclass(frozen=True)
class Evaluation:
    """Certified value of a policy: lower <= P(satisfied) <= upper, and trust at episode end.

    end_mass: probability of each way an episode ends ("accepted", "rejected", "destination",
    "cap") plus "pruned" (branches not followed to the end; the width of the interval).
    """

    policy: str
    lower: float
    upper: float
    expected_final_trust: float
    final_trust_lower: float
    final_trust_upper: float
    expected_junctions: float
    fallback_probability: float
    end_mass: dict[str, float]
    nodes: int
    max_frontier: int
    seconds: float
    belief_rule: str
    fallback_after: int | None
    max_junctions: int
    reference_accepted: float | None = None   # mass the reference reading accepts (`reference`)
    pruning: dict | None = None   # the joint unfolding's limits and what each cut (evaluate_joint)

    @property
    def gap(self) -> float:
        return self.upper - self.lower

    @property
    def satisfaction_probability(self) -> float:
        """Midpoint of the certified interval (equal to both ends when nothing was pruned)."""
        return 0.5 * (self.lower + self.upper)

    def to_dict(self) -> dict:
        out = asdict(self)
        for optional in ("reference_accepted", "pruning"):
            if out[optional] is None:
                del out[optional]
        out["gap"] = self.gap
        out["satisfaction_probability"] = self.satisfaction_probability
        return out


def accepted_bounds(accepted: float, pruned: float) -> tuple[float, float]:
    """[lower, upper] of P(accepted) from the accepted and pruned masses.

    Summed path masses can round past 1; a probability cannot, and upper >= lower must hold.
    """
    lower = min(accepted, 1.0)
    return lower, min(1.0, lower + pruned)


@dataclass(eq=False)
class PathLedger:
    """Whole nodes end accepted, rejected, at the destination or the cap, or are pruned."""

    levels: np.ndarray
    prune_below: float
    max_nodes: int
    reference: bool = False
    mass: dict = field(default_factory=lambda: {"accepted": 0.0, "rejected": 0.0, "destination": 0.0,
                                                "cap": 0.0, "pruned": 0.0})
    trust_sum: float = 0.0      # Σ P(end node) E[θ | node] over ended (non-pruned) nodes
    junction_sum: float = 0.0
    fallback_mass: float = 0.0
    ref_mass: float = 0.0

    def end(self, frontier, rows: np.ndarray, reason: str, level: int) -> None:
        p = frontier.probability[rows]
        if self.reference:
            state: ObservedState = frontier.state
            self.ref_mass += float(p[state.reference_accepting(rows)].sum())
        self.mass[reason] += float(p.sum())
        self.trust_sum += float(p @ (frontier.state.posterior[rows] @ self.levels))
        self.junction_sum += float(p.sum()) * level

    def settle(self, frontier, level: int, out_of_time: bool) -> np.ndarray | None:
        """End the nodes the DFA has decided; the open ones (None: past the deadline, they are cut
        and their mass widens [lower, upper])."""
        accepted, rejected, _ = frontier.state.masses()
        accepted, rejected = accepted > 0, rejected > 0
        self.end(frontier, accepted, "accepted", level)
        self.end(frontier, rejected, "rejected", level)
        open_nodes = ~(accepted | rejected)
        if out_of_time:
            self.cut(frontier, open_nodes, level, "past_deadline")
            return None
        return open_nodes

    def prune(self, frontier, alive: np.ndarray, level: int) -> np.ndarray:
        """Cut the open nodes below `prune_below`; the ones followed."""
        tiny = alive & (frontier.probability < self.prune_below)
        self.mass["pruned"] += float(frontier.probability[tiny].sum())
        return alive & ~tiny

    def cut(self, frontier, rows, level: int, why: str) -> None:
        self.mass["pruned"] += float(frontier.probability[rows].sum())

    def trim(self, frontier, level: int) -> np.ndarray | None:
        """Beyond `max_nodes`, the rows kept (the likeliest) in their order; None: all."""
        probability = frontier.probability
        if probability.size <= self.max_nodes:
            return None
        order = np.argsort(probability)
        dropped = order[: probability.size - self.max_nodes]
        self.mass["pruned"] += float(probability[dropped].sum())
        return np.sort(order[probability.size - self.max_nodes:])

    def evaluation(self, nodes: int, max_frontier: int, **fields) -> Evaluation:
        pruned = self.mass["pruned"]
        ended = 1.0 - pruned
        lower, upper = accepted_bounds(self.mass["accepted"], pruned)
        return Evaluation(
            lower=lower, upper=upper,
            expected_final_trust=self.trust_sum / ended if ended > 0 else float("nan"),
            final_trust_lower=self.trust_sum + pruned * float(self.levels.min()),
            final_trust_upper=self.trust_sum + pruned * float(self.levels.max()),
            expected_junctions=self.junction_sum / ended if ended > 0 else float("nan"),
            fallback_probability=self.fallback_mass, end_mass=self.mass, nodes=nodes,
            max_frontier=max_frontier,
            reference_accepted=min(self.ref_mass, 1.0) if self.reference else None, **fields)


CUTS = ("below_threshold", "beyond_budget", "past_deadline")


@dataclass(eq=False)
class TypeMasses:
    """Accepted and cut live mass of each driver type, for a hidden index that is (type, trust)
    (policies/belief/driver_types.py): J's blocks, one per type, split what JointLedger adds up."""

    n_types: int
    accepting: np.ndarray                   # bool [n_q]
    live: np.ndarray                        # bool [n_q]: neither accepting nor rejecting
    accepted: np.ndarray = field(init=False)
    unknown: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.accepted = np.zeros(self.n_types)
        self.unknown = np.zeros(self.n_types)

    def add(self, p: np.ndarray, joint: np.ndarray, cut: bool) -> None:
        m, n_hidden, n_q = joint.shape
        blocks = joint.reshape(m, self.n_types, n_hidden // self.n_types, n_q).sum(axis=2)   # [m, K, q]
        self.accepted += p @ blocks[:, :, self.accepting].sum(axis=2)
        if cut:
            self.unknown += p @ blocks[:, :, self.live].sum(axis=2)

    def bounds(self, weights: np.ndarray) -> list[tuple[float, float]]:
        """[lower, upper] of P(accepted | type k) for each type of prior weight weights[k]."""
        return [accepted_bounds(float(a / w), float(u / w)) if w > 0 else (float("nan"), float("nan"))
                for a, u, w in zip(self.accepted, self.unknown, weights, strict=True)]


@dataclass(eq=False)
class JointLedger:
    """Accepted and rejected masses by J(θ, q); the live mass by end reason (unknown when cut)."""

    levels: np.ndarray
    prune_below: float
    max_nodes: int
    mass: dict = field(default_factory=lambda: {"accepted": 0.0, "rejected": 0.0, "destination": 0.0,
                                                "cap": 0.0, "pruned": 0.0, "settled": 0.0})
    trust_sum: float = 0.0
    junction_sum: float = 0.0
    ended_mass: float = 0.0
    fallback_mass: float = 0.0
    cut_mass: dict = field(default_factory=lambda: dict.fromkeys(CUTS, 0.0))
    cut_nodes: dict = field(default_factory=lambda: dict.fromkeys(CUTS, 0))
    first_cut_level: int | None = None
    live: np.ndarray | None = None          # the level's live mass per node (settle -> prune)
    types: TypeMasses | None = None          # the masses by driver type too (a population's)

    def end(self, frontier, rows, reason: str, level: int, why: str = "") -> None:
        """Nodes ending here: accepted and rejected mass by J, the live rest by `reason` (for
        "pruned", `why` names the cut)."""
        p = frontier.probability[rows]
        accepted, rejected, live = frontier.state.masses(rows)
        self.mass["accepted"] += float(p @ accepted)
        self.mass["rejected"] += float(p @ rejected)
        self.mass[reason] += float(p @ live)
        if self.types is not None:
            self.types.add(p, frontier.state.joint[rows], reason == "pruned")
        if reason == "pruned" and p.size:
            self.cut_mass[why] += float(p @ live)
            self.cut_nodes[why] += int(p.size)
            self.first_cut_level = level if self.first_cut_level is None else self.first_cut_level
        if reason != "pruned":
            self.ended_mass += float(p.sum())
            self.trust_sum += float(p @ (frontier.state.posterior[rows] @ self.levels))
            self.junction_sum += float(p.sum()) * level

    def settle(self, frontier, level: int, out_of_time: bool) -> np.ndarray | None:
        """End the nodes without live mass; past the deadline cut the rest (None: stop)."""
        _, _, self.live = frontier.state.masses()
        settled = self.live <= 0
        self.end(frontier, settled, "settled", level)
        if out_of_time:
            self.end(frontier, ~settled, "pruned", level, "past_deadline")
            return None
        return ~settled

    def prune(self, frontier, alive: np.ndarray, level: int) -> np.ndarray:
        """Cut the open nodes whose live mass is below `prune_below` (what pruning a node costs:
        its accepted mass is counted anyway)."""
        tiny = alive & (frontier.probability * self.live < self.prune_below)
        self.end(frontier, tiny, "pruned", level, "below_threshold")
        return alive & ~tiny

    def cut(self, frontier, rows, level: int, why: str) -> None:
        self.end(frontier, rows, "pruned", level, why)

    def trim(self, frontier, level: int) -> np.ndarray | None:
        """Beyond `max_nodes`, the rows kept: least live mass dropped first (the width pruning
        adds is the live mass it drops); None: all."""
        probability = frontier.probability
        if probability.size <= self.max_nodes:
            return None
        order = np.argsort(probability * frontier.state.masses()[2], kind="stable")
        dropped = np.zeros(probability.size, dtype=bool)
        dropped[order[: probability.size - self.max_nodes]] = True
        self.end(frontier, dropped, "pruned", level + 1, "beyond_budget")
        return np.flatnonzero(~dropped)

    def evaluation(self, nodes: int, max_frontier: int, time_limit: float | None = None,
                   **fields) -> Evaluation:
        lower, upper = accepted_bounds(self.mass["accepted"], self.mass["pruned"])
        ended = self.ended_mass
        return Evaluation(
            lower=lower, upper=upper,
            expected_final_trust=self.trust_sum / ended if ended > 0 else float("nan"),
            final_trust_lower=self.trust_sum + (1.0 - ended) * float(self.levels.min()),
            final_trust_upper=self.trust_sum + (1.0 - ended) * float(self.levels.max()),
            expected_junctions=self.junction_sum / ended if ended > 0 else float("nan"),
            fallback_probability=self.fallback_mass, end_mass=self.mass, nodes=nodes,
            max_frontier=max_frontier,
            pruning={"prune_below": self.prune_below, "max_nodes": self.max_nodes,
                     "time_limit": time_limit, "pruned_mass": self.cut_mass,
                     "pruned_nodes": self.cut_nodes, "first_pruned_level": self.first_cut_level},
            **fields)


# What ended the unfolding of a BoundLedger or an UnboundedLedger (`stopped`): "convergence" (what
# is unresolved, open or dropped, is at most the tolerance: none within a cap, 1e-9 over unbounded
# time), "node cap" (nodes dropped beyond `max_nodes` of a level left more live mass unknown),
# "junction cap" (an unbounded unfolding reached its `max_junctions` with live mass open) or
# "deadline". The caps are among work_clock.CAPS, so `stopped_by` names them as they are.
UNFOLDING_STOPS = ("convergence", "node cap", "junction cap", "deadline")


@dataclass(eq=False)
class BoundLedger:
    """Accepted mass of the nodes that end (no live mass, or the cap) and the live mass of the
    nodes cut (unknown): [lower, upper] of P(accepted within `max_junctions`); what ended it
    (`stopped`, UNFOLDING_STOPS) from the live mass it dropped beyond `max_nodes` (`dropped`)
    and whether the deadline cut nodes (`late`)."""

    max_junctions: int
    max_nodes: int
    accepted: float = 0.0
    unknown: float = 0.0
    dropped: float = 0.0
    late: bool = False
    fallback_mass: float = 0.0   # a policy without episode rules has no fallback: stays 0
    # the level's (accepted, rejected, live) (settle -> prune)
    live_masses: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def end(self, frontier, rows, reason: str, level: int) -> None:
        accepted, _, _ = frontier.state.masses(rows)
        self.accepted += float(frontier.probability[rows] @ accepted)

    def cut(self, frontier, rows, level: int, why: str) -> None:
        accepted, _, live = frontier.state.masses(rows)
        p = frontier.probability[rows]
        self.accepted += float(p @ accepted)
        self.unknown += float(p @ live)
        self.late = self.late or why == "past_deadline"

    def settle(self, frontier, level: int, out_of_time: bool) -> np.ndarray | None:
        """End the nodes without live mass and, at the cap, every node (None: stop)."""
        if out_of_time:
            self.cut(frontier, slice(None), level, "past_deadline")
            return None
        self.live_masses = frontier.state.masses()
        accepted, _, live = self.live_masses
        ending = (live <= 0) | (level == self.max_junctions)
        self.accepted += float(frontier.probability[ending] @ accepted[ending])
        return ~ending

    def prune(self, frontier, go: np.ndarray, level: int) -> np.ndarray:
        """Beyond `max_nodes` open nodes, the least likely are cut."""
        return self._drop(frontier, go, frontier.probability)

    def _drop(self, frontier, go: np.ndarray, rank: np.ndarray) -> np.ndarray:
        """`go` without the open nodes beyond the `max_nodes` of largest `rank`: their accepted
        mass counts, their live mass is unknown."""
        if go.sum() <= self.max_nodes:
            return go
        if self.live_masses is None:
            raise TypeError("prune reads the level's masses, which settle computes first")
        accepted, _, live = self.live_masses
        mass = frontier.probability
        order = np.argsort(-np.where(go, rank, -np.inf), kind="stable")
        dropped = np.zeros(mass.size, dtype=bool)
        dropped[order[self.max_nodes:]] = True
        dropped &= go
        self.accepted += float(mass[dropped] @ accepted[dropped])
        lost = float(mass[dropped] @ live[dropped])
        self.unknown += lost
        self.dropped += lost
        return go & ~dropped

    def trim(self, frontier, level: int) -> None:
        return None

    @property
    def stopped(self) -> str:
        """What ended the unfolding (UNFOLDING_STOPS): within the cap, exact unless nodes were
        dropped or cut at the deadline."""
        if self.late:
            return "deadline"
        return "node cap" if self.dropped > 0 else "convergence"

    def bounds(self) -> tuple[float, float]:
        return accepted_bounds(self.accepted, self.unknown)


# Added to the unresolved mass per level of an unbounded evaluation, as a margin for the rounding
# of the double-precision masses summed and multiplied along the way (a level's masses carry a
# relative error of order 1e-16 per operation over about a thousand operations per node).
ROUNDING_MARGIN_PER_LEVEL = 1e-12


@dataclass(eq=False)
class UnboundedLedger(BoundLedger):
    """BoundLedger without a junction cap: [lower, upper] of P(accepted eventually). Every level's
    accepted mass is a lower bound (accepting states are absorbing), and it only grows with the
    levels, like value iteration from below on the policy's chain of beliefs; the live mass of the
    open nodes is still unresolved and counts in `upper` only. The unfolding stops when that mass
    is at most `tolerance`, at the deadline or after `max_junctions` junctions (`stopped`)."""

    tolerance: float = 1e-9
    levels_done: int = 0
    open_live: float = 0.0     # the live mass still open when it stopped (none at the deadline's cut)
    capped: bool = False       # stopped at max_junctions with more than `tolerance` open

    def settle(self, frontier, level: int, out_of_time: bool) -> np.ndarray | None:
        self.levels_done = level
        if out_of_time:
            self.cut(frontier, slice(None), level, "past_deadline")
            return None
        self.live_masses = frontier.state.masses()
        accepted, _, live = self.live_masses
        open_live = float(frontier.probability @ live)
        if open_live <= self.tolerance or level == self.max_junctions:
            self.open_live = open_live
            self.capped = open_live > self.tolerance
            self.cut(frontier, slice(None), level, "cap" if self.capped else "converged")
            return None
        ending = live <= 0
        self.accepted += float(frontier.probability[ending] @ accepted[ending])
        return ~ending

    def prune(self, frontier, go: np.ndarray, level: int) -> np.ndarray:
        """Beyond `max_nodes` open nodes, those with the least live mass are cut: what a cut
        leaves unknown is its live mass, and with no cap a node's accepted mass is already
        counted, so this keeps the most of what is still to be decided (measured on the
        unbounded phi1_trust: docs/peers.md)."""
        if self.live_masses is None:
            raise TypeError("prune reads the level's masses, which settle computes first")
        return self._drop(frontier, go, frontier.probability * self.live_masses[2])

    @property
    def stopped(self) -> str:
        """What ended the unfolding (UNFOLDING_STOPS): the deadline, the junction cap, or the open
        live mass at most the tolerance: "convergence" if with the live mass dropped beyond
        `max_nodes` it still is, else "node cap" (the width of [lower, upper] is then mostly what
        was dropped, which no longer unfolding resolves)."""
        if self.late:
            return "deadline"
        if self.capped:
            return "junction cap"
        return "convergence" if self.open_live + self.dropped <= self.tolerance else "node cap"

    @property
    def converged(self) -> bool:
        return self.stopped == "convergence"

    def bounds(self) -> tuple[float, float]:
        margin = ROUNDING_MARGIN_PER_LEVEL * (self.levels_done + 1)
        lower, upper = accepted_bounds(self.accepted, self.unknown + margin)
        return max(lower - margin, 0.0), upper
