"""The plain trust POMDP as pomdp-py objects, so that pomdp-py's planners (POUCT) can run on it.

Owns the pomdp-py view of `TrustPOMDP` (see docs/model.md, "The model"): states
(road, trust), actions (next junction), observations (incident, h, e), the transition,
observation, reward and policy models, beliefs over trust as a histogram or particles, and
`build_problem`, which assembles a pomdp_py.POMDP (agent + environment).
The task here is plain reachability: reward 1 on first reaching a target set of roads, after
which the state is absorbing. (policies/pomdp_py/pouct.py plans on the product with a spec's
DFA instead; the two are kept apart.)

One modelling choice: in the trust POMDP the observation (h, e) after a move depends on the
trust *before* the move, while pomdp-py's observation model sees only the next state. So a
state also carries the (h, e) drawn with the move into it, and the observation model is
deterministic: P(o | s', a) = [o = (incident of s'.road, s'.h, s'.e)]. Summing the histogram
update over (h, e) gives exactly the Bayes filter of policies/model/trust_pomdp.py.
Every random draw goes through the numpy Generator passed in (pomdp-py's own `random` module
is never used: the belief classes override `random()`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

import numpy as np
import pomdp_py

from trustroute.policies.model.trust_pomdp import TrustPOMDP

BeliefKind = Literal["histogram", "particles"]


@dataclass(frozen=True)
class RouteState(pomdp_py.State):
    """(road index into town.states, trust index 0..n-1) plus the (h, e) drawn with the move
    into this state (0, 0 for the start state)."""

    road: int
    trust: int
    human_action: int = 0
    performance: int = 0


@dataclass(frozen=True)
class RouteAction(pomdp_py.Action):
    """Drive to this next junction (a neighbour of the current road's end)."""

    junction: str


@dataclass(frozen=True)
class RouteObservation(pomdp_py.Observation):
    """(incident index of the road just driven, h: 0 standstill / 1 takeover, e: 0 succ / 1 fail)."""

    incident: int
    human_action: int
    performance: int


def _draw(probabilities: np.ndarray, rng: np.random.Generator) -> int:
    cdf = np.cumsum(probabilities)
    return min(int(np.searchsorted(cdf, rng.random() * cdf[-1], side="right")), cdf.size - 1)


@dataclass(frozen=True, eq=False)
class RouteTask:
    """The POMDP and the target roads (indices); shared by all the models below."""

    pomdp: TrustPOMDP
    targets: frozenset[int]

    def next_road(self, road: int, junction: str) -> int:
        """Road index reached by driving to `junction` from road `road` (ValueError if illegal)."""
        actions = self.pomdp.action_junctions[road]
        if junction not in actions:
            raise ValueError(f"{junction} is not a legal move from {self.pomdp.town.states[road]}")
        return self.pomdp.next_state(road, actions.index(junction))

    def is_target(self, road: int) -> bool:
        return road in self.targets

    def observation_of(self, state: RouteState) -> RouteObservation:
        return RouteObservation(int(self.pomdp.road_incident[state.road]), state.human_action,
                                state.performance)


class TransitionModel(pomdp_py.TransitionModel):
    """P(s' | s, a) = P(h | θ, inc) P(e | θ, inc) T[inc][h][e](θ, θ') on the road a leads to,
    inc its incident; a target road is absorbing."""

    def __init__(self, task: RouteTask, rng: np.random.Generator) -> None:
        self.task, self.rng = task, rng

    def probability(self, next_state: RouteState, state: RouteState, action: RouteAction) -> float:
        if self.task.is_target(state.road):
            return float(next_state == state)
        road = self.task.next_road(state.road, action.junction)
        if next_state.road != road:
            return 0.0
        inc = self.task.pomdp.road_incident[road]
        return float(self.task.pomdp.weighted_transition[inc, next_state.human_action,
                                                         next_state.performance, state.trust,
                                                         next_state.trust])

    def sample(self, state: RouteState, action: RouteAction) -> RouteState:
        if self.task.is_target(state.road):
            return state
        pomdp = self.task.pomdp
        road = self.task.next_road(state.road, action.junction)
        inc = pomdp.road_incident[road]
        h = int(self.rng.random() < pomdp.driver.takeover_probability[inc, state.trust])
        e = int(self.rng.random() < pomdp.driver.failure_probability[inc, state.trust])
        trust = _draw(pomdp.driver.trust_transition[inc, h, e, state.trust], self.rng)
        return RouteState(road, trust, h, e)

    def get_all_states(self) -> list[RouteState]:
        pomdp = self.task.pomdp
        return [RouteState(x, t, h, e) for x in range(pomdp.n_states) for t in range(pomdp.n_trust)
                for h in (0, 1) for e in (0, 1)]


class ObservationModel(pomdp_py.ObservationModel):
    """Deterministic given the next state: o = (incident of s'.road, s'.h, s'.e)."""

    def __init__(self, task: RouteTask) -> None:
        self.task = task

    def probability(self, observation: RouteObservation, next_state: RouteState,
                    action: RouteAction) -> float:
        return float(observation == self.task.observation_of(next_state))

    def sample(self, next_state: RouteState, action: RouteAction) -> RouteObservation:
        return self.task.observation_of(next_state)

    def get_all_observations(self) -> list[RouteObservation]:
        n_inc = len(self.task.pomdp.driver.incident_types)
        return [RouteObservation(i, h, e) for i in range(n_inc) for h in (0, 1) for e in (0, 1)]


class RewardModel(pomdp_py.RewardModel):
    """1 on the move that first reaches a target road, else 0 (targets are absorbing)."""

    def __init__(self, task: RouteTask) -> None:
        self.task = task

    def probability(self, reward: float, state: RouteState, action: RouteAction,
                    next_state: RouteState) -> float:
        return float(reward == self.sample(state, action, next_state))

    def sample(self, state: RouteState, action: RouteAction, next_state: RouteState) -> float:
        return float(not self.task.is_target(state.road) and self.task.is_target(next_state.road))


class PolicyModel(pomdp_py.RolloutPolicy):
    """The legal next junctions of the current road (no U-turns except at dead ends); rollouts
    and samples pick one uniformly with the Generator."""

    def __init__(self, task: RouteTask, rng: np.random.Generator) -> None:
        self.task, self.rng = task, rng
        self.actions = tuple(tuple(RouteAction(j) for j in junctions)
                             for junctions in task.pomdp.action_junctions)

    def get_all_actions(self, state: RouteState | None = None, history=None) -> list[RouteAction]:
        if state is None:
            raise ValueError("the legal actions depend on the road: pass the state")
        return list(self.actions[state.road])

    def probability(self, action: RouteAction, state: RouteState) -> float:
        legal = self.actions[state.road]
        return 1.0 / len(legal) if action in legal else 0.0

    def sample(self, state: RouteState) -> RouteAction:
        legal = self.actions[state.road]
        return legal[int(self.rng.integers(len(legal)))]

    def rollout(self, state: RouteState, history=None) -> RouteAction:
        return self.sample(state)


class TrustHistogram(pomdp_py.Histogram):
    """Exact belief over states (the road is known, so only trust and the last (h, e) vary)."""

    def __init__(self, histogram: dict, rng: np.random.Generator) -> None:
        super().__init__(histogram)
        self.rng = rng

    def random(self):
        states = list(self.histogram)
        weights = np.array([self.histogram[s] for s in states], dtype=float)
        return states[_draw(weights, self.rng)]


class TrustParticles(pomdp_py.Particles):
    """Unweighted particles; sampling through the Generator."""

    def __init__(self, particles: list, rng: np.random.Generator) -> None:
        super().__init__(particles)
        self.rng = rng

    def random(self):
        particles = self.particles
        return particles[int(self.rng.integers(len(particles)))]


def trust_marginal(belief: pomdp_py.GenerativeDistribution, n_trust: int) -> np.ndarray:
    """P(θ) under a histogram or particle belief."""
    out = np.zeros(n_trust)
    if isinstance(belief, pomdp_py.Histogram):
        for state, p in belief.histogram.items():
            out[state.trust] += p
    else:
        for state in belief.particles:
            out[state.trust] += 1.0
    total = out.sum()
    return out / total if total > 0 else out


def initial_belief(pomdp: TrustPOMDP, road: int, rng: np.random.Generator,
                   kind: BeliefKind = "histogram", n_particles: int = 1000,
                   trust_distribution: np.ndarray | None = None) -> pomdp_py.GenerativeDistribution:
    """Belief at a known road with trust ~ `trust_distribution` (the model's initial belief)."""
    dist = pomdp.initial_belief if trust_distribution is None else np.asarray(trust_distribution)
    if kind == "histogram":
        return TrustHistogram({RouteState(road, t): float(p) for t, p in enumerate(dist) if p > 0}, rng)
    if kind == "particles":
        return TrustParticles([RouteState(road, _draw(dist, rng)) for _ in range(n_particles)], rng)
    raise ValueError(f"unknown belief kind {kind!r}; use 'histogram' or 'particles'")


def update_belief(belief: pomdp_py.GenerativeDistribution, task: RouteTask, action: RouteAction,
                  observation: RouteObservation, rng: np.random.Generator
                  ) -> pomdp_py.GenerativeDistribution:
    """The belief after (action, observation).

    Histogram: pomdp-py's exact update B'(s') ∝ O(o|s',a) Σs T(s'|s,a) B(s), over the states of
    the road the action leads to. Particles: each particle is resampled with weight
    P(h, e | θ, inc) and then moved by T[inc][h][e](θ, ·) (the exact proposal, so a possible
    observation never empties the set). An impossible observation raises ValueError.
    """
    roads = {s.road for s in (belief.histogram if isinstance(belief, pomdp_py.Histogram)
                              else belief.particles)}
    if len(roads) != 1:
        raise ValueError("the belief must sit on one known road")
    (road,) = roads
    if task.is_target(road):
        return belief   # absorbing: the task is over
    next_road = task.next_road(road, action.junction)
    pomdp = task.pomdp
    if isinstance(belief, pomdp_py.Histogram):
        space = [RouteState(next_road, t, observation.human_action, observation.performance)
                 for t in range(pomdp.n_trust)]
        updated = pomdp_py.update_histogram_belief(
            belief, action, observation, ObservationModel(task), TransitionModel(task, rng),
            next_state_space=space)
        if sum(updated.histogram.values()) <= 0:
            raise ValueError(f"observation {observation} has probability 0 under the belief")
        return TrustHistogram({s: p for s, p in updated.histogram.items() if p > 0}, rng)
    inc, h, e = observation.incident, observation.human_action, observation.performance
    thetas = np.array([s.trust for s in belief.particles])
    weights = pomdp.observation_likelihood[inc, h, e, thetas]
    if inc != pomdp.road_incident[next_road] or weights.sum() <= 0:
        raise ValueError(f"observation {observation} has probability 0 under the belief")
    chosen = rng.choice(thetas.size, size=thetas.size, p=weights / weights.sum())
    moved = [RouteState(next_road, _draw(pomdp.driver.trust_transition[inc, h, e, thetas[k]], rng), h, e)
             for k in chosen]
    return TrustParticles(moved, rng)


def build_models(pomdp: TrustPOMDP, targets: Iterable[str], rng: np.random.Generator
                 ) -> tuple[RouteTask, TransitionModel, ObservationModel, RewardModel, PolicyModel]:
    target_roads = list(targets)
    for road in target_roads:
        if road not in pomdp.town.states:
            raise ValueError(f"target {road!r} is not a directed road of the town")
    task = RouteTask(pomdp, frozenset(pomdp.town.state_index(r) for r in target_roads))
    return (task, TransitionModel(task, rng), ObservationModel(task), RewardModel(task),
            PolicyModel(task, rng))


def build_problem(pomdp: TrustPOMDP, start: str, targets: Iterable[str], rng: np.random.Generator,
                  belief: BeliefKind = "histogram", n_particles: int = 1000,
                  true_trust: int | None = None) -> tuple[pomdp_py.POMDP, RouteTask]:
    """A pomdp_py.POMDP: the agent (belief at `start`, trust from the model's initial belief)
    and an environment whose true trust index is `true_trust` or drawn from the initial belief."""
    task, transition, observation, reward, policy = build_models(pomdp, targets, rng)
    road = pomdp.town.state_index(start)
    agent = pomdp_py.Agent(initial_belief(pomdp, road, rng, belief, n_particles), policy, transition,
                           observation, reward)
    trust = _draw(pomdp.initial_belief, rng) if true_trust is None else int(true_trust)
    environment = pomdp_py.Environment(RouteState(road, trust), transition, reward)
    return pomdp_py.POMDP(agent, environment, name="trust-route"), task
