"""The AV's side of one episode, pure Python (no SUMO): route, belief, DFA state, end, logs.

Shared by the SUMO engine (harness/simulation/episode.py) and the model engine
(harness/simulation/model_engine.py) so the two can never disagree on the logic. The rules
(when an episode ends, the fallback, legal moves) are policies/routing/episode_rules.py's, the
same the exact evaluation uses:

- position 0 is (spec.start, initial belief); q_0 = the compiled spec's initial state;
- at every position the rules end the episode ("accepted", "rejected", "destination", "cap")
  or ask the policy (with the fallback) for the next junction;
- after driving a road the AV observes (incident, takeover, performance), applies its belief
  filter (setup.belief_rule) and steps the DFA on (road, new belief), belief labels decided
  exactly on the history's word where floats cannot decide them, as synthesis and `evaluate` do
  (policies/belief/exact_labels.py).

With a driver population (docs/driver_types.md) the AV's model is the type-aware one: its belief
is over (type, trust); the roads table logs its trust marginal (so belief atoms of the analysis
read it as for a single model) and `type_belief` gives the type marginal.

Row 0 of the roads table is the start road: incident "none" and no observation (takeover,
performance and reported_trust null), trust_before = trust_after = the initial true trust. The
table's schema is `trustroute.core.dataset.ROADS_SCHEMA` (docs/dataset.md).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import pandas as pd
import pyarrow as pa

from trustroute.core.dataset import ROADS_SCHEMA, frame_from_table, table_from_rows
from trustroute.networks.town import NO_INCIDENT, Town
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.belief.driver_types import trust_marginal, type_belief
from trustroute.policies.belief.exact_labels import ExactLabels, exact_labels, symbol_code
from trustroute.policies.belief.problem import DRIVER_TYPES, PLAIN, TRUST_STATE, Problem, case_of
from trustroute.policies.belief.trust_state_filter import joint_filter
from trustroute.policies.logic.compiled import CompiledSpec, compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import TrustPOMDP, build_pomdp, checked_belief_rule
from trustroute.policies.routing.episode_rules import (
    DEFAULT_JUNCTION_CAP,
    checked_choice,
    dfa_verdict,
    end_before_choice,
    episode_policy,
)
from trustroute.policies.routing.fallback import DEFAULT_FALLBACK_AFTER
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

PERFORMANCE_INDEX = {"succ": 0, "fail": 1}


@dataclass(frozen=True, eq=False)
class EpisodeSetup:
    """Everything an episode needs besides the policy, the driver and the seed."""

    town: Town
    driver_model: DriverModel      # the nominal model the AV's belief filter uses
    spec: Spec
    junction_cap: int = DEFAULT_JUNCTION_CAP
    fallback_after: int | None = DEFAULT_FALLBACK_AFTER
    report_every: int = 1          # the driver reports trust every N roads
    belief_rule: str = "bayes"
    # The AV's trust POMDP of town and driver_model when its caller holds it already (a Problem's:
    # `of`); None: built on first use
    pomdp: TrustPOMDP | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.pomdp is not None and (self.pomdp.town is not self.town
                                       or self.pomdp.driver is not self.driver_model):
            raise ValueError("EpisodeSetup: `pomdp` is not the trust POMDP of its town and driver model")

    @classmethod
    def of(cls, problem: Problem, **rules) -> EpisodeSetup:
        """The setup of `problem` (its town, AV model, spec as the AV reads it, and trust POMDP),
        with `rules` (junction_cap, fallback_after, report_every, belief_rule) where given."""
        return cls(town=problem.town, driver_model=problem.driver, spec=problem.spec,
                   pomdp=problem.pomdp, **rules)

    @functools.cached_property
    def model(self) -> EpisodeModel:
        """The arrays the setup's episodes read, built on first use and held by the setup: every
        episode run with one setup (a study's cell, the gymnasium environment's episodes) shares
        them and their memos."""
        pomdp = self.pomdp if self.pomdp is not None else build_pomdp(self.town, self.driver_model)
        return EpisodeModel(pomdp=pomdp, compiled=compile_spec(self.spec, self.town))


@dataclass(frozen=True)
class DrivenRoad:
    """One road as driven: the AV's observation on it (the road's incident, whether the driver
    took over, the AV's performance "succ" or "fail"), the driver's true trust before and after,
    the trust the driver reported (None: no report on this road), and the simulator's clock
    entering and leaving the road (NaN: the model engine has no simulator clock)."""

    road: str
    incident: str
    takeover: bool
    performance: str
    trust_before: int
    trust_after: int
    reported_trust: int | None = None
    sim_time_in: float = math.nan
    sim_time_out: float = math.nan


@dataclass(frozen=True, eq=False)
class EpisodeModel:
    """The arrays an episode reads: the AV's trust POMDP and the spec compiled on the town."""

    pomdp: TrustPOMDP
    compiled: CompiledSpec
    # Memoised filter and DFA steps, shared by the episodes of one setup. Episodes start from one
    # initial belief and meet few distinct observation sequences, so most steps repeat; a hit
    # returns the very floats the computation gave (the same seed still gives the same logs).
    updates: dict = field(default_factory=dict, repr=False)
    exact: dict = field(default_factory=dict, repr=False)    # belief rule -> ExactLabels

    def labels(self, rule: str) -> ExactLabels:
        """The belief labels of the AV's filter under `rule` (word ids shared by the episodes)."""
        found = self.exact.get(rule)
        if found is None:
            found = self.exact[rule] = exact_labels(self.pomdp, self.compiled.labeller,
                                                    checked_belief_rule(rule))
        return found


MAX_MEMO = 200_000   # entries per memo before it is cleared (bounded memory in long studies)


def _memo_put(memo: dict, key, value):
    if len(memo) >= MAX_MEMO:
        memo.clear()
    memo[key] = value
    return value


def reports_after_road(road_number: int, report_every: int) -> bool:
    """Whether the driver is asked for a trust report when road `road_number` (1 for the first
    road after the start) closes: every `report_every`-th road."""
    return road_number % report_every == 0


class EpisodeTracker:
    """Route, online Bayes belief, DFA state and the roads table of one episode."""

    def __init__(self, setup: EpisodeSetup, policy: RoutingPolicy, episode_id: str,
                 initial_trust: int, sim_time: float = 0.0) -> None:
        if setup.junction_cap < 0:
            raise ValueError(f"junction_cap must be >= 0, got {setup.junction_cap}")
        if setup.report_every < 1:
            raise ValueError(f"report_every must be >= 1, got {setup.report_every}")
        self.belief_rule = checked_belief_rule(setup.belief_rule)
        self.setup = setup
        self.episode_id = str(episode_id)
        model = setup.model
        self._pomdp, self._compiled = model.pomdp, model.compiled
        self._memo = model.updates
        self.dfa = model.compiled.dfa
        self.policy = episode_policy(policy, setup.town, setup.spec, setup.fallback_after)
        start = setup.spec.start
        self.route: list[str] = [start]
        self.belief: np.ndarray = np.asarray(self._pomdp.initial_belief, dtype=float).copy()
        self.belief.setflags(write=False)   # shared with the policies' contexts (and the memo's beliefs)
        # The belief's bytes (the memo keys) and the form the roads table logs, kept beside it: a
        # memo hit then needs no numpy call (cheap while SUMO's stepping keeps the caches cold).
        self._belief_bytes = self.belief.tobytes()
        self._belief_logged = self._logged(self.belief)
        self._labels = model.labels(self.belief_rule)
        self.word = 0       # the belief's word (exact_labels.ExactFilter), 0 = the prior's
        # How the AV follows the spec's DFA is the problem's case (policies/belief/problem.py): the
        # state itself when it is observed, else the joint belief J(θ, q) (DFA_TRACKING).
        tracking = DFA_TRACKING[case_of(setup.driver_model, setup.spec)]
        self._dfa: DFATracking = tracking(self, int(initial_trust))
        self.dfa_state: int = self._dfa.told
        self.end_reason: str | None = self._verdict()
        self.fallback_fired = False
        self.fallback_junction: int | None = None   # junctions driven when the fallback first drove
        self._chosen: str | None = None            # next junction chosen at the current road
        self._asked: DecisionContext | None = None  # the decision point waiting for its choice
        self._rows: list[dict] = [{
            "episode_id": self.episode_id, "index": 0, "directed_road": start, "action": None,
            "incident": NO_INCIDENT, "takeover": None, "performance": None,
            "trust_before": int(initial_trust), "trust_after": int(initial_trust),
            "reported_trust": None, "belief_before": self._belief_logged,
            "belief_after": self._belief_logged, "dfa_state": self.dfa_state, "fallback": False,
            "sim_time_in": float(sim_time), "sim_time_out": None,
        }]

    # -- internals -----------------------------------------------------------
    def _logged(self, belief: np.ndarray) -> tuple[float, ...]:
        """The belief as the roads table logs it: over trust (the trust marginal of a type-aware
        belief; the belief itself otherwise). A tuple: rows and the memo share it."""
        return tuple(trust_marginal(self.setup.driver_model, belief).tolist())

    def type_belief(self) -> np.ndarray:
        """The AV's current belief over the driver's type (one entry for a single driver model)."""
        return type_belief(self.setup.driver_model, self.belief)

    def _context(self) -> DecisionContext:
        # The belief is read-only (never changed in place: a road gives a new array), so the
        # context can hold it without a copy.
        return DecisionContext(route=tuple(self.route), dfa_state=self.dfa_state, belief=self.belief,
                               joint=self._dfa.context_joint())

    def _verdict(self) -> str | None:
        """rules 1-2 of the episode (the DFA tracking's verdict)."""
        return self._dfa.verdict()

    @property
    def satisfied(self) -> bool:
        """The spec holds on this episode's trace (the DFA tracking's reading)."""
        return self._dfa.satisfied(self.end_reason)

    # -- the episode's API ---------------------------------------------------
    @property
    def junctions(self) -> int:
        return len(self.route) - 1

    @property
    def road(self) -> str:
        return self.route[-1]

    def decision_point(self) -> DecisionContext | None:
        """What the AV knows where the next junction is to be chosen, or None when the episode is
        over (end_reason set: the DFA's verdict, the policy's destination, the junction cap). Asked
        twice at the same road it gives the same context (the policy's `finished` asked once)."""
        if self.end_reason is not None or self._chosen is not None:
            return None
        if self._asked is not None:
            return self._asked
        context = self._context()
        end = end_before_choice(self.policy, context, self.setup.junction_cap)
        if end is not None:
            self.end_reason = end
            return None
        self._asked = context
        return context

    def choose(self, junction: str) -> str:
        """The junction chosen at the decision point (by the episode's policy, or by whoever steps
        the episode): checked legal, recorded on the current road's row; returns it."""
        context = self._asked
        if context is None:
            raise ValueError(f"episode {self.episode_id}: no junction to choose here "
                             f"({self.end_reason or 'ask decision_point first'})")
        decision = checked_choice(self.policy, context, self.setup.town, junction)
        fired = decision.fallback
        if fired and not self.fallback_fired:
            self.fallback_fired = True
            self.fallback_junction = self.junctions
        self._rows[-1]["action"] = junction
        self._rows[-1]["fallback"] = bool(fired)
        self._chosen, self._asked = junction, None
        return junction

    def next_junction(self) -> str | None:
        """The policy's choice at the current road (with the 20-junction fallback); None when the
        episode is over (end_reason set). Asking twice at the same road gives the same answer."""
        if self._chosen is not None:
            return self._chosen
        context = self.decision_point()
        if context is None:
            return None
        return self.choose(self.policy.next_junction(context))

    def expected_road(self) -> str | None:
        """The road the vehicle drives next (after next_junction), or None."""
        if self._chosen is None:
            return None
        return self.setup.town.successor(self.road, self._chosen)

    def record_road(self, driven: DrivenRoad) -> None:
        """Append the row of a driven road, apply the belief filter on (incident, takeover,
        performance), step the DFA, and set end_reason when the DFA accepts or rejects.
        NaN sim times are stored as nulls (the model engine has no simulator clock)."""
        road, incident, takeover = driven.road, driven.incident, driven.takeover
        performance = driven.performance
        if self.end_reason is not None:
            raise ValueError(f"episode {self.episode_id} is over ({self.end_reason}); no more roads")
        expected = self.expected_road()
        if expected is None:
            raise ValueError("record_road before next_junction: the policy has not chosen a road")
        if road != expected:
            raise ValueError(f"drove {road!r} but the policy chose {expected!r}")
        if performance not in PERFORMANCE_INDEX:
            raise ValueError(f"performance must be 'succ' or 'fail', got {performance!r}")
        incident_index = self.setup.driver_model.incident_index(incident)
        before, before_logged = self.belief, self._belief_logged
        h, e = int(bool(takeover)), PERFORMANCE_INDEX[performance]
        key = ("belief", self._belief_bytes, incident_index, bool(takeover), performance,
               self.setup.belief_rule)
        entry = self._memo.get(key)
        if entry is None:
            # An observation the AV's model deems impossible keeps the prior (TrustPOMDP.filter).
            posterior, possible = self._pomdp.filter(before, incident_index, h, e, rule=self.belief_rule)
            after = posterior[0]
            after.setflags(write=False)
            entry = _memo_put(self._memo, key,
                              (after, after.tobytes(), self._logged(after), bool(possible[0])))
        after, self._belief_bytes, self._belief_logged, possible = entry
        self.belief = after
        if possible:
            self.word = self._labels.filter.extend_one(self.word, int(symbol_code(incident_index, h, e)))
        self.dfa_state = self._dfa.step(road, incident_index, h, e, int(driven.trust_after))
        self.route.append(road)
        self._chosen = None
        self._rows[-1]["sim_time_out"] = float(driven.sim_time_in)
        reported = driven.reported_trust
        self._rows.append({
            "episode_id": self.episode_id, "index": len(self._rows), "directed_road": road,
            "action": None, "incident": incident, "takeover": bool(takeover), "performance": performance,
            "trust_before": int(driven.trust_before), "trust_after": int(driven.trust_after),
            "reported_trust": None if reported is None else int(reported),
            "belief_before": before_logged,
            "belief_after": self._belief_logged, "dfa_state": self.dfa_state, "fallback": False,
            "sim_time_in": float(driven.sim_time_in), "sim_time_out": float(driven.sim_time_out),
        })
        self.end_reason = self._verdict()

    def should_report(self) -> bool:
        """Whether the driver reports trust on the road about to be recorded (every report_every)."""
        return reports_after_road(len(self._rows), self.setup.report_every)

    def roads_table(self) -> pa.Table:
        """The roads table of the dataset (ROADS_SCHEMA) as Arrow, one row per position."""
        return table_from_rows(self._rows, ROADS_SCHEMA)

    def roads_frame(self) -> pd.DataFrame:
        """The roads table of the dataset (ROADS_SCHEMA), one row per position."""
        return frame_from_table(self.roads_table())

    def summary(self, wall_seconds: float, sim_seconds: float) -> dict:
        """The episode summary dict; mean_trust is the mean true trust over all positions."""
        trust = [row["trust_after"] for row in self._rows]
        return {
            "episode_id": self.episode_id,
            "satisfied": self.satisfied,
            "junctions": self.junctions,
            "takeovers": int(sum(bool(row["takeover"]) for row in self._rows)),
            "final_trust": int(trust[-1]),
            # sum / n of small integers is exact before the one division: the float np.mean gives
            "mean_trust": sum(trust) / len(trust),
            "end_reason": self.end_reason if self.end_reason is not None else "",
            "fallback_fired": self.fallback_fired,
            "sim_seconds": float(sim_seconds),
            "wall_seconds": float(wall_seconds),
        }


class DFATracking(Protocol):
    """How the AV follows the spec's DFA: the state it is told, its joint belief for the policy's
    context, the episode's verdict and satisfaction, and a step after a driven road."""

    told: int

    def context_joint(self) -> np.ndarray | None: ...

    def step(self, road: str, incident: int, h: int, e: int, trust_after: int) -> int: ...

    def verdict(self) -> str | None: ...

    def satisfied(self, end_reason: str | None) -> bool: ...


class ObservedDFA:
    """The DFA state is a function of the observations (PLAIN, DRIVER_TYPES): stepped on
    (road, AV belief), memoised across the process's episodes."""

    def __init__(self, tracker: EpisodeTracker, initial_trust: int) -> None:
        self.tracker = tracker
        key = ("initial", tracker._belief_bytes)
        state = tracker._memo.get(key)
        if state is None:
            compiled = tracker._compiled
            state = _memo_put(tracker._memo, key, int(tracker._labels.step(
                np.array([compiled.dfa.initial]), np.array([compiled.start]), tracker.belief[None],
                np.zeros(1, dtype=np.int64))[0]))
        self.told = state

    def context_joint(self) -> None:
        return None

    def step(self, road: str, incident: int, h: int, e: int, trust_after: int) -> int:
        tracker = self.tracker
        key = ("dfa", self.told, road, tracker._belief_bytes, tracker.word, tracker.belief_rule)
        state = tracker._memo.get(key)
        if state is None:
            x = tracker._compiled.town.state_index(road)
            state = _memo_put(tracker._memo, key, int(tracker._labels.step(
                np.array([self.told]), np.array([x]), tracker.belief[None],
                np.array([tracker.word]))[0]))
        self.told = state
        return state

    def verdict(self) -> str | None:
        return dfa_verdict(self.tracker._compiled, self.told)

    def satisfied(self, end_reason: str | None) -> bool:
        return end_reason == "accepted"


class HiddenDFA:
    """The formula tests the hidden trust (TRUST_STATE): the AV tracks the joint belief J(θ, q)
    (its DFA state told is the most probable under J) and the episode ends when J has no live
    mass; the true DFA state, read on the driver's true trust, decides whether the episode
    satisfied the spec (also when the AV could not tell and it ended at the destination or the cap)."""

    def __init__(self, tracker: EpisodeTracker, initial_trust: int) -> None:
        self.tracker = tracker
        compiled = tracker._compiled
        self.filter = joint_filter(tracker._pomdp, compiled.dfa, compiled.labeller)
        self.joint = self.filter.initial(compiled.start, tracker.belief)[0]
        self.posterior = tracker.belief.copy()        # the exact (Bayes) θ filter J moves with
        self.told = int(self.filter.likeliest_q(self.joint[None])[0])
        self.true_state = self.true_step(compiled.dfa.initial, compiled.start, initial_trust)

    def context_joint(self) -> np.ndarray:
        return self.joint.copy()

    def true_step(self, q: int, x: int, trust_level: int) -> int:
        """The DFA state after position (x, true trust level, the AV's belief) from q."""
        tracker = self.tracker
        theta = tracker.setup.driver_model.trust_levels.index(int(trust_level))
        truth = tracker._labels.truth(tracker.belief[None], np.array([tracker.word]))
        return int(tracker._compiled.labeller.step(np.array([q]), np.array([x]), tracker.belief[None],
                                                   np.array([theta]), belief_truth=truth)[0])

    def step(self, road: str, incident: int, h: int, e: int, trust_after: int) -> int:
        """J after driving `road` and observing (incident, h, e); the told and the true DFA state."""
        tracker = self.tracker
        x = np.array([tracker.setup.town.state_index(road)])
        inc = np.array([incident])
        # The exact (Bayes) θ filter's posterior and the observation's probability, as the exact
        # evaluation computes them (the AV's belief is this posterior under the Bayes rule).
        posterior, probability = tracker._pomdp.belief_update(self.posterior[None], inc, h, e,
                                                              rule="bayes")
        if probability[0] > 0:
            self.posterior = posterior[0]
            self.joint = self.filter.update(self.joint[None], posterior, tracker.belief[None], x,
                                            (inc, h, e), probability, np.array([tracker.word]),
                                            tracker._labels)[0]
        # else: an observation the AV's model deems impossible: J stays (as the belief does).
        self.told = int(self.filter.likeliest_q(self.joint[None])[0])
        self.true_state = self.true_step(self.true_state, int(x[0]), trust_after)
        return self.told

    def verdict(self) -> str | None:
        _, _, live = self.filter.masses(self.joint[None])
        if live[0] > 0:
            return None
        return "accepted" if self.tracker._compiled.accepting[self.true_state] else "rejected"

    def satisfied(self, end_reason: str | None) -> bool:
        return bool(self.tracker._compiled.accepting[self.true_state])


DFA_TRACKING: dict[str, Callable[[EpisodeTracker, int], DFATracking]] = {
    PLAIN: ObservedDFA, DRIVER_TYPES: ObservedDFA, TRUST_STATE: HiddenDFA}
