"""The model engine: episodes in the abstract trust POMDP, without SUMO, for fast what-ifs.

Two paths with the same episode rules (policies/routing/episode_rules.py):

- `run_model_episode(setup, policy, driver, episode_id, seed)`: one episode through the very
  `EpisodeTracker` the SUMO engine uses, with a `SyntheticDriver`; writes the full roads table
  of the contract (sim times NaN, no kinematics). This is what studies run.
- `simulate_batch(...)`: many episodes at once in numpy (one array row per episode, one loop
  iteration per junction level), returning only the per-episode summaries. Policy decisions
  are asked once per distinct (route, DFA state, AV belief) per level, or once per route when
  the policy declares its decision route-determined (the trust-free policy, the fallback phase),
  so it scales to the 100k-episodes-per-minute benchmark. tests/harness/simulation/test_model_engine.py
  checks that both paths agree in distribution and with policies.evaluation.plain.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from trustroute.core.dataset import KINEMATICS_SCHEMA, frame_from_table
from trustroute.harness.simulation.episode import EpisodeRecord
from trustroute.harness.simulation.episode_tracker import EpisodeSetup, EpisodeTracker, episode_model
from trustroute.participants.driver_model import DriverModel
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.belief.problem import dfa_is_hidden
from trustroute.policies.routing.episode_rules import (
    ACCEPTED,
    END_REASONS,
    REJECTED,
    decide,
    dfa_verdicts,
    episode_policy,
)
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

END_CODES: tuple[str, ...] = ("", *END_REASONS)  # index 0: still running


def empty_kinematics() -> pd.DataFrame:
    return frame_from_table(KINEMATICS_SCHEMA.empty_table())


def run_model_episode(
    setup: EpisodeSetup, policy: RoutingPolicy, driver: SyntheticDriver, episode_id: str, seed: int
) -> EpisodeRecord:
    """One episode in the trust POMDP. `seed` is recorded by the caller only: every draw is the
    driver's (its Generator), so the episode is a function of the driver's seed."""
    del seed  # the model engine has no simulator of its own to seed
    started = time.perf_counter()
    town = setup.town
    tracker = EpisodeTracker(setup, policy, episode_id, initial_trust=driver.trust, sim_time=math.nan)
    while tracker.next_junction() is not None:
        road = tracker.expected_road()
        incident = town.incident(road)
        before = driver.trust
        took_over = driver.decides_takeover(incident)
        performance = driver.performance(incident)
        after = driver.move_trust(incident, took_over, performance)
        reported = driver.report_trust() if tracker.should_report() else None
        tracker.record_road(
            road, incident, took_over, performance, before, after, reported, math.nan, math.nan
        )
    summary = tracker.summary(wall_seconds=time.perf_counter() - started, sim_seconds=math.nan)
    return EpisodeRecord(summary=summary, roads=tracker.roads_frame(), kinematics=empty_kinematics())


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


def _draw_rows(cdf: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One draw per row of a CDF matrix [n, k] (inverse CDF, robust to totals of 1 ± 1e-9)."""
    u = rng.random(cdf.shape[0]) * cdf[:, -1]
    return np.minimum((cdf <= u[:, None]).sum(axis=1), cdf.shape[1] - 1)


def simulate_batch(
    setup: EpisodeSetup,
    policy: RoutingPolicy,
    count: int,
    rng: np.random.Generator,
    drivers: Sequence[DriverModel] | None = None,
    driver_index: np.ndarray | None = None,
) -> BatchResult:
    """`count` model-engine episodes at once; returns the per-episode summaries.

    drivers: the true driver models (default: the AV's nominal model); episode i is driven by
    drivers[driver_index[i]] (default: all by drivers[0]). Initial trust is drawn from each
    driver's initial distribution, as SyntheticDriver does. The episode rules are the tracker's
    (policies/routing/episode_rules.py). Specs with trust-state atoms need the joint belief of
    the episode tracker: run them through `run_model_episode`.
    """
    if dfa_is_hidden(setup.driver_model, setup.spec):
        raise ValueError(f"spec {setup.spec.name!r} has trust-state atoms: the batch path does not "
                         "track the joint belief; run its episodes with run_model_episode")
    started = time.perf_counter()
    town = setup.town
    model = episode_model(setup)
    pomdp, compiled = model.pomdp, model.compiled
    policy = episode_policy(policy, town, setup.spec, setup.fallback_after)
    drivers = list(drivers) if drivers is not None else [setup.driver_model]
    index = (
        np.zeros(count, dtype=np.int64) if driver_index is None else np.asarray(driver_index, dtype=np.int64)
    )
    if index.shape != (count,):
        raise ValueError(f"driver_index must have {count} entries, got shape {index.shape}")
    nominal = setup.driver_model
    incident_map = np.array([[d.incident_index(inc) for inc in nominal.incident_types] for d in drivers])
    takeover = np.stack([d.takeover_probability for d in drivers])  # [k, inc, θ]
    failure = np.stack([d.failure_probability for d in drivers])
    transition_cdf = np.cumsum(np.stack([d.trust_transition for d in drivers]), axis=-1)
    initial_cdf = np.cumsum(np.stack([d.initial_belief for d in drivers]), axis=-1)
    levels = np.asarray(nominal.trust_levels, dtype=float)
    successor_of = {
        (x, j): town.state_index(town.successor(road, j))
        for x, road in enumerate(town.states)
        for j in town.actions(road)
    }

    theta = _draw_rows(initial_cdf[index], rng)
    start = town.state_index(setup.spec.start)
    road = np.full(count, start, dtype=np.int64)
    belief = np.tile(np.asarray(pomdp.initial_belief, dtype=float), (count, 1))
    q = compiled.initial_states(belief)
    routes: list[tuple[str, ...]] = [(setup.spec.start,)]
    children: dict[tuple[int, int], int] = {}
    route_id = np.zeros(count, dtype=np.int64)
    end = np.zeros(count, dtype=np.int64)  # index into END_CODES; 0 = running
    junctions = np.zeros(count, dtype=np.int64)
    takeovers = np.zeros(count, dtype=np.int64)
    trust_sum = levels[theta].copy()
    fired_any = np.zeros(count, dtype=bool)
    policy_calls = 0

    for _level in range(setup.junction_cap + 1):
        running = end == 0
        verdict = dfa_verdicts(compiled, q)
        end[running & (verdict == ACCEPTED)] = END_CODES.index("accepted")
        end[running & (verdict == REJECTED)] = END_CODES.index("rejected")
        live = np.flatnonzero(end == 0)
        if live.size == 0:
            break
        chosen = np.full(live.size, -1, dtype=np.int64)
        finished = np.zeros(live.size, dtype=bool)
        fired = np.zeros(live.size, dtype=bool)
        order = np.argsort(route_id[live], kind="stable")
        ids, starts = np.unique(route_id[live][order], return_index=True)
        bounds = np.append(starts, live.size)
        for r, rid in enumerate(ids.tolist()):
            members = order[bounds[r] : bounds[r + 1]]
            first = live[members[0]]
            context = DecisionContext(route=routes[rid], dfa_state=int(q[first]), belief=belief[first])
            if policy.route_determined(context):
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
                policy_calls += 1
                decision = decide(policy, ctx, town, setup.junction_cap)
                if decision.end is not None:
                    finished[group] = decision.end == "destination"
                    continue
                chosen[group] = successor_of[(int(road[first]), decision.junction)]
                fired[group] = decision.fallback
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
        # The driver: takeover from trust before the road, AV performance, trust moves.
        k = index[movers]
        inc_av = pomdp.road_incident[x2]
        inc = incident_map[k, inc_av]
        th = theta[movers]
        h = (rng.random(movers.size) < takeover[k, inc, th]).astype(np.int64)
        e = (rng.random(movers.size) < failure[k, inc, th]).astype(np.int64)
        new_theta = _draw_rows(transition_cdf[k, inc, h, e, th], rng)
        theta[movers] = new_theta
        # The AV: Bayes filter on (incident, h, e), then the DFA on (road, new belief).
        posterior, _ = pomdp.belief_update(belief[movers], inc_av, h, e, rule=setup.belief_rule)
        impossible = ~(posterior.sum(axis=1) > 0)
        posterior[impossible] = belief[movers][impossible]
        belief[movers] = posterior
        q[movers] = compiled.step(q[movers], x2, posterior)
        road[movers] = x2
        junctions[movers] += 1
        takeovers[movers] += h
        trust_sum[movers] += levels[new_theta]
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
    )
