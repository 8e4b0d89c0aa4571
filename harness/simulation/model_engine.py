"""The model engine: episodes in the abstract trust POMDP, without SUMO, for fast what-ifs.

Two paths with the same episode rules (policies/routing/episode_rules.py) and the same driver
step (participants/driver_step.py: takeover, the AV's performance, trust move, in that order):

- `ModelEpisode(setup, policy, driver, episode_id, seed)`: one episode through the very
  `EpisodeTracker` the SUMO engine uses, with a `SyntheticDriver`, stepped from outside like the
  SUMO engine's episode (stepping.py); writes the full roads table of the contract (sim times NaN,
  no kinematics). `run_model_episode` drives it with its policy to the end: what studies run.
- `simulate_batch(...)`: many episodes at once in numpy (one array row per episode, one loop
  iteration per junction level), returning only the per-episode summaries. Policy decisions
  are asked once per distinct (route, DFA state, AV belief) per level, or once per route when
  the policy declares its decision route-determined (the trust-free policy, the fallback phase),
  so it scales to the 100k-episodes-per-minute benchmark. On one episode it draws what the
  per-episode path draws from the same seed when the driver gives no reports.
- `monte_carlo(pomdp, spec, policy, episodes, rng)`: the batch path on one episode after the
  other (a planner that draws while it plans, POUCT, gets one decision per episode and draws
  between that episode's driver draws): satisfaction rate, its standard error, time per decision.

tests/harness/simulation/test_model_engine.py checks that the paths agree draw for draw or in
distribution, and with policies.evaluation.plain.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from trustroute.core.dataset import INCIDENTS_SCHEMA, KINEMATICS_SCHEMA
from trustroute.harness.simulation.episode_record import EpisodeRecord
from trustroute.harness.simulation.episode_tracker import (
    DrivenRoad,
    EpisodeModel,
    EpisodeSetup,
    EpisodeTracker,
)
from trustroute.harness.simulation.stepping import DecisionPoint, End, run_to_end
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel, DriverTables, driver_tables
from trustroute.participants.driver_step import draw_initial_trust, draw_report_batch, draw_step
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.belief.av_step import AVStep
from trustroute.policies.belief.exact_labels import exact_labels
from trustroute.policies.belief.problem import dfa_is_hidden
from trustroute.policies.logic.compiled import CompiledSpec, compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP, checked_belief_rule
from trustroute.policies.routing.episode_rules import (
    ACCEPTED,
    DEFAULT_JUNCTION_CAP,
    END_REASONS,
    REJECTED,
    decide,
    dfa_verdicts,
    episode_policy,
)
from trustroute.policies.routing.fallback import DEFAULT_FALLBACK_AFTER
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

END_CODES: tuple[str, ...] = ("", *END_REASONS)  # index 0: still running
# The model engine has no kinematics or incident objects: one empty (immutable) table each
NO_KINEMATICS = KINEMATICS_SCHEMA.empty_table()
NO_INCIDENTS = INCIDENTS_SCHEMA.empty_table()


class ModelEpisode:
    """One episode in the trust POMDP, stepped from outside (stepping.py) like the SUMO engine's:
    `advance()` drives the chosen road (the driver's step, the tracker's record) and stops at the
    next decision point or the end. `seed` is recorded by the caller only: every draw is the
    driver's (its Generator), so the episode is a function of the driver's seed."""

    def __init__(self, setup: EpisodeSetup, policy: RoutingPolicy, driver: SyntheticDriver,
                 episode_id: str, seed: int) -> None:
        del seed  # the model engine has no simulator of its own to seed
        self.started = time.perf_counter()
        self.setup = setup
        self.driver = driver
        self.tracker = EpisodeTracker(setup, policy, episode_id, initial_trust=driver.trust,
                                      sim_time=math.nan)
        self._point: DecisionPoint | None = None   # the decision point waiting for its answer
        self._end: End | None = None

    @property
    def policy(self) -> RoutingPolicy:
        return self.tracker.policy

    def advance(self) -> DecisionPoint | End:
        if self._end is not None:
            return self._end
        tracker = self.tracker
        if self._point is not None and tracker.expected_road() is None:   # not answered yet
            return self._point
        road = tracker.expected_road()
        if road is not None:
            self._drive(road)
        context = tracker.decision_point()
        if context is not None:
            self._point = DecisionPoint(context, self.setup.town.actions(context.road))
            return self._point
        summary = tracker.summary(wall_seconds=time.perf_counter() - self.started, sim_seconds=math.nan)
        # Arrow tables: the record converts to pandas only if asked, so a study writing parts never does
        self._end = End(EpisodeRecord(summary=summary, roads=tracker.roads_table(), kinematics=NO_KINEMATICS,
                                      incidents=NO_INCIDENTS))
        return self._end

    def choose(self, junction: str) -> None:
        self.tracker.choose(junction)

    def close(self) -> None:
        """Nothing to close: the model engine holds no simulator."""

    def _drive(self, road: str) -> None:
        """The driver's step on `road` (takeover, the AV's performance, trust move, report) and the
        tracker's record of it."""
        driver, tracker = self.driver, self.tracker
        incident = self.setup.town.incident(road)
        before = driver.trust
        took_over = driver.decides_takeover(incident)
        performance = driver.performance(incident)
        after = driver.move_trust(incident, took_over, performance)
        reported = driver.report_trust() if tracker.should_report() else None
        tracker.record_road(DrivenRoad(road, incident, took_over, performance, before, after, reported))


def run_model_episode(
    setup: EpisodeSetup, policy: RoutingPolicy, driver: SyntheticDriver, episode_id: str, seed: int
) -> EpisodeRecord:
    """One episode in the trust POMDP driven by its own policy (`ModelEpisode` stepped to its end)."""
    return run_to_end(ModelEpisode(setup, policy, driver, episode_id, seed))


# -- the vectorised path -------------------------------------------------------------------------


@dataclass(frozen=True)
class BatchResult:
    """Per-episode summaries of `simulate_batch` (arrays of length n) and its timing."""

    satisfied: np.ndarray
    junctions: np.ndarray
    takeovers: np.ndarray
    final_trust: np.ndarray
    mean_trust: np.ndarray
    end_reason: np.ndarray  # str
    fallback_fired: np.ndarray
    policy_calls: int
    seconds: float
    decision_seconds: float = 0.0   # of `seconds`, in the policy's decisions
    # mean reported trust level per episode (NaN without a report), when reports were drawn
    mean_reported: np.ndarray | None = None
    trace: BatchTrace | None = None   # what each episode drove and observed, when asked for


    def frame(self) -> pd.DataFrame:
        return pd.DataFrame(
            {
                "satisfied": self.satisfied,
                "junctions": self.junctions,
                "takeovers": self.takeovers,
                "final_trust": self.final_trust,
                "mean_trust": self.mean_trust,
                "end_reason": self.end_reason,
                "fallback_fired": self.fallback_fired,
            }
        )


@dataclass(frozen=True, eq=False)
class BatchTrace:
    """What `simulate_batch`'s episodes drove and observed, int arrays [n, junction_cap + 1] padded
    beyond each episode's `lengths` (junctions + 1): position 0 is the start road, position t the
    t-th road driven, with its incident (index in the AV's model's list), takeover (0/1) and the
    AV's performance (0 succ, 1 fail), and the level the driver reported there (-1: none), as the
    roads table of the episode would log them (docs/dataset.md)."""

    roads: np.ndarray
    incident: np.ndarray
    takeover: np.ndarray
    performance: np.ndarray
    reports: np.ndarray
    lengths: np.ndarray


@dataclass(frozen=True, eq=False)
class _Sampled:
    """What sampled episodes of one (town, AV model, spec, policy, true drivers) read."""

    town: Town
    pomdp: TrustPOMDP
    compiled: CompiledSpec
    start: str
    policy: RoutingPolicy             # wrapped with the episode's fallback
    drivers: DriverTables             # the true drivers (kinds), on the AV's incident list
    junction_cap: int
    belief_rule: BeliefRule
    successor: dict[tuple[int, str], int]


def _sampled(model: EpisodeModel, spec: Spec, policy: RoutingPolicy, drivers: Sequence[DriverModel],
             junction_cap: int, fallback_after: int | None, belief_rule: BeliefRule) -> _Sampled:
    """The batch path's arrays: the AV's model and compiled spec (`model`, on its town), the
    policy with the episode's fallback, the true drivers' tables and the episode's rules."""
    pomdp, compiled = model.pomdp, model.compiled
    town = pomdp.town
    if dfa_is_hidden(pomdp.driver, spec):
        raise ValueError(f"spec {spec.name!r} has trust-state atoms: the batch path does not "
                         "track the joint belief; run its episodes with run_model_episode")
    return _Sampled(
        town=town, pomdp=pomdp, compiled=compiled, start=spec.start,
        policy=episode_policy(policy, town, spec, fallback_after),
        drivers=driver_tables(drivers, pomdp.driver.incident_types),
        junction_cap=junction_cap, belief_rule=belief_rule,
        successor={(x, j): town.state_index(town.successor(road, j))
                   for x, road in enumerate(town.states) for j in town.actions(road)})


def simulate_batch(
    setup: EpisodeSetup,
    policy: RoutingPolicy,
    count: int,
    rng: np.random.Generator,
    drivers: Sequence[DriverModel] | None = None,
    driver_index: np.ndarray | None = None,
    report_accuracy: float | None = None,
    trace: bool = False,
) -> BatchResult:
    """`count` model-engine episodes at once; returns the per-episode summaries.

    drivers: the true driver models (default: the AV's nominal model); episode i is driven by
    drivers[driver_index[i]] (default: all by drivers[0]). Initial trust is drawn from each
    driver's initial distribution, as SyntheticDriver does. The episode rules are the tracker's
    (policies/routing/episode_rules.py). Specs with trust-state atoms need the joint belief of
    the episode tracker: run them through `run_model_episode`.

    report_accuracy: also draw the drivers' trust reports (every setup.report_every roads, through
    `draw_report_batch`) and return their mean per episode; the reports then take uniforms of
    their own after each level's step, so the episodes are the per-episode path's in
    distribution, not draw for draw. None (the default): no reports, no draws for them.

    trace: also return what every episode drove and observed (`BatchTrace`), for a belief source
    other than the AV's own filter; it draws nothing.
    """
    index = (
        np.zeros(count, dtype=np.int64) if driver_index is None else np.asarray(driver_index, dtype=np.int64)
    )
    if index.shape != (count,):
        raise ValueError(f"driver_index must have {count} entries, got shape {index.shape}")
    true_drivers = list(drivers) if drivers is not None else [setup.driver_model]
    sampled = _sampled(setup.model, setup.spec, policy, true_drivers, setup.junction_cap,
                       setup.fallback_after, checked_belief_rule(setup.belief_rule))
    return _unfold(sampled, index, rng, None if report_accuracy is None else
                   (float(report_accuracy), setup.report_every), trace)


def _decisions(sampled: _Sampled, live: np.ndarray, route_id: np.ndarray, routes: list[tuple[str, ...]],
               q: np.ndarray, belief: np.ndarray, road: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float]:
    """The policy's decisions for the live episodes, asked once per distinct (route, DFA state,
    belief), or once per route when the policy declares its decision route-determined: (next road
    or -1, finished at the destination, fallback drove, policy calls, seconds in the policy)."""
    chosen = np.full(live.size, -1, dtype=np.int64)
    finished = np.zeros(live.size, dtype=bool)
    fired = np.zeros(live.size, dtype=bool)
    calls, seconds = 0, 0.0
    order = np.argsort(route_id[live], kind="stable")
    ids, starts = np.unique(route_id[live][order], return_index=True)
    bounds = np.append(starts, live.size)
    for r, rid in enumerate(ids.tolist()):
        members = order[bounds[r] : bounds[r + 1]]
        first = live[members[0]]
        context = DecisionContext(route=routes[rid], dfa_state=int(q[first]), belief=belief[first])
        if sampled.policy.route_determined(context):
            groups = [(members, context)]
        else:
            keyed: dict[tuple[int, bytes], list[int]] = {}
            for m in members.tolist():
                keyed.setdefault((int(q[live[m]]), belief[live[m]].tobytes()), []).append(m)
            groups = [
                (
                    np.array(ms),
                    DecisionContext(route=routes[rid], dfa_state=key[0], belief=belief[live[ms[0]]]),
                )
                for key, ms in keyed.items()
            ]
        for group, ctx in groups:
            calls += 1
            tick = time.perf_counter()
            decision = decide(sampled.policy, ctx, sampled.town, sampled.junction_cap)
            seconds += time.perf_counter() - tick
            if decision.end is not None:
                finished[group] = decision.end == "destination"
                continue
            if decision.junction is None:
                raise KeyError(f"the episode rules neither ended the episode nor chose a junction at "
                               f"road {int(road[first])}")
            chosen[group] = sampled.successor[(int(road[first]), decision.junction)]
            fired[group] = decision.fallback
    return chosen, finished, fired, calls, seconds


def _unfold(sampled: _Sampled, index: np.ndarray, rng: np.random.Generator,
            reports: tuple[float, int] | None = None, trace: bool = False) -> BatchResult:
    """Episodes driven by drivers of kinds `index`, level by level: the verdicts, the policy's
    decisions, the driver's step (participants/driver_step.py) for every episode that moves, the
    AV's filter and DFA. Draws: initial trust of every episode, then per level the policy's (if it
    draws) and the driver step's (takeover, performance, trust, each over the movers in order)."""
    started = time.perf_counter()
    pomdp, compiled, town = sampled.pomdp, sampled.compiled, sampled.town
    count = index.size
    levels = np.asarray(pomdp.driver.trust_levels, dtype=float)
    theta = draw_initial_trust(sampled.drivers, index, rng)
    road = np.full(count, town.state_index(sampled.start), dtype=np.int64)
    belief = np.tile(np.asarray(pomdp.initial_belief, dtype=float), (count, 1))
    # belief labels as the tracker reads them (policies/belief/exact_labels.py): per episode the
    # word of its belief's history
    labels = exact_labels(pomdp, compiled.labeller, sampled.belief_rule)
    av = AVStep(pomdp, labels, sampled.belief_rule)
    word = np.zeros(count, dtype=np.int64)
    q = np.asarray(labels.step(np.full(count, compiled.dfa.initial), road, belief, word), dtype=np.int64)
    routes: list[tuple[str, ...]] = [(sampled.start,)]
    children: dict[tuple[int, int], int] = {}
    route_id = np.zeros(count, dtype=np.int64)
    end = np.zeros(count, dtype=np.int64)  # index into END_CODES; 0 = running
    junctions = np.zeros(count, dtype=np.int64)
    takeovers = np.zeros(count, dtype=np.int64)
    trust_sum = levels[theta].copy()
    fired_any = np.zeros(count, dtype=bool)
    report_sum = np.zeros(count, dtype=float)
    report_count = np.zeros(count, dtype=np.int64)
    policy_calls, decision_seconds = 0, 0.0
    traced = _new_trace(count, sampled.junction_cap, road) if trace else None

    for _level in range(sampled.junction_cap + 1):
        running = end == 0
        verdict = dfa_verdicts(compiled, q)
        end[running & (verdict == ACCEPTED)] = END_CODES.index("accepted")
        end[running & (verdict == REJECTED)] = END_CODES.index("rejected")
        live = np.flatnonzero(end == 0)
        if live.size == 0:
            break
        chosen, finished, fired, calls, seconds = _decisions(sampled, live, route_id, routes, q, belief, road)
        policy_calls += calls
        decision_seconds += seconds
        end[live[finished]] = END_CODES.index("destination")
        capped = ~finished & (chosen < 0)
        end[live[capped]] = END_CODES.index("cap")
        go = ~finished & ~capped
        movers, x2 = live[go], chosen[go]
        fired_any[movers] |= fired[go]
        if movers.size == 0:
            break
        # New route ids: one per distinct (old route, next road).
        for m, (rid, x) in enumerate(zip(route_id[movers].tolist(), x2.tolist(), strict=True)):
            key = (rid, x)
            child = children.get(key)
            if child is None:
                child = len(routes)
                routes.append(routes[rid] + (town.states[x],))
                children[key] = child
            route_id[movers[m]] = child
        # The driver's step (participants/driver_step.py): takeover from trust before the road,
        # AV performance, trust moves.
        inc_av = pomdp.road_incident[x2]
        h, e, new_theta = draw_step(sampled.drivers, index[movers], inc_av, theta[movers], rng)
        theta[movers] = new_theta
        # The AV: its filter on (incident, h, e), then the DFA on (road, new belief) (AVStep).
        belief[movers], word[movers], q[movers], _ = av.step(belief[movers], word[movers], q[movers], x2,
                                                             (inc_av, h, e))
        road[movers] = x2
        junctions[movers] += 1
        takeovers[movers] += h
        trust_sum[movers] += levels[new_theta]
        if reports is not None:
            reporters = movers[junctions[movers] % reports[1] == 0]
            said = draw_report_batch(theta[reporters], reports[0], levels.size, rng)
            report_sum[reporters] += levels[said]
            report_count[reporters] += 1
            if traced is not None:
                traced.reports[reporters, junctions[reporters]] = levels[said]
        if traced is not None:
            at = junctions[movers]
            traced.roads[movers, at], traced.incident[movers, at] = x2, inc_av
            traced.takeover[movers, at], traced.performance[movers, at] = h, e
    else:
        end[end == 0] = END_CODES.index("cap")

    return BatchResult(
        satisfied=end == END_CODES.index("accepted"),
        junctions=junctions,
        takeovers=takeovers,
        final_trust=levels[theta].astype(np.int64),
        mean_trust=trust_sum / (junctions + 1),
        end_reason=np.array(END_CODES, dtype=object)[end],
        fallback_fired=fired_any,
        policy_calls=policy_calls,
        seconds=time.perf_counter() - started,
        decision_seconds=decision_seconds,
        mean_reported=None if reports is None else np.divide(
            report_sum, report_count, out=np.full(count, np.nan), where=report_count > 0),
        trace=None if traced is None else replace(traced, lengths=junctions + 1),
    )


def _new_trace(count: int, junction_cap: int, start: np.ndarray) -> BatchTrace:
    """An empty trace of `count` episodes starting on the roads `start` (lengths set at the end)."""
    shape = (count, junction_cap + 1)   # small integers: a plan traces thousands of episodes at once
    roads = np.zeros(shape, dtype=np.int32)
    roads[:, 0] = start
    return BatchTrace(roads=roads, incident=np.zeros(shape, dtype=np.int8),
                      takeover=np.zeros(shape, dtype=np.int8), performance=np.zeros(shape, dtype=np.int8),
                      reports=np.full(shape, -1, dtype=np.int8), lengths=np.zeros(count, dtype=np.int64))


@dataclass(frozen=True)
class MonteCarloResult:
    """`monte_carlo`'s estimate: satisfaction rate and its standard error, mean final true trust,
    junctions driven (decisions) and the time in the policy per decision."""

    policy: str
    episodes: int
    satisfaction: float
    standard_error: float
    mean_final_trust: float
    decisions: int
    seconds_per_decision: float
    seconds: float


def monte_carlo(pomdp: TrustPOMDP, spec: Spec, policy: RoutingPolicy, episodes: int,
                rng: np.random.Generator, fallback_after: int | None = DEFAULT_FALLBACK_AFTER,
                max_junctions: int = DEFAULT_JUNCTION_CAP,
                belief_rule: BeliefRule = "bayes") -> MonteCarloResult:
    """Run `policy` (with the study's fallback unless None) in the trust model `episodes` times,
    true trust drawn from `pomdp.driver`: the batch path on one episode after the other, so a
    policy that draws from `rng` while it plans (POUCT) draws between its own episode's driver
    draws, and no two episodes share a decision."""
    started = time.perf_counter()
    model = EpisodeModel(pomdp=pomdp, compiled=compile_spec(spec, pomdp.town))
    sampled = _sampled(model, spec, policy, [pomdp.driver], max_junctions, fallback_after, belief_rule)
    runs = [_unfold(sampled, np.zeros(1, dtype=np.int64), rng) for _ in range(episodes)]
    satisfied = np.array([bool(run.satisfied[0]) for run in runs])
    decisions = int(sum(int(run.junctions[0]) for run in runs))
    decision_seconds = sum(run.decision_seconds for run in runs)
    rate = float(satisfied.mean()) if episodes else float("nan")
    return MonteCarloResult(
        policy=sampled.policy.name, episodes=episodes, satisfaction=rate,
        standard_error=float(np.sqrt(rate * (1 - rate) / episodes)) if episodes else float("nan"),
        mean_final_trust=float(np.mean([run.final_trust[0] for run in runs])) if episodes else float("nan"),
        decisions=decisions, seconds_per_decision=decision_seconds / decisions if decisions else 0.0,
        seconds=time.perf_counter() - started)
