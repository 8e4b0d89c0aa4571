"""pomdp-py's POUCT on the trust POMDP × spec DFA product (reward 1 on acceptance), as a baseline.

Owns `POUCTPolicy`, a RoutingPolicy that plans each decision online with pomdp-py's POUCT
from the AV's current belief; its satisfaction rate and time per decision are measured with the
model engine's `monte_carlo` (harness/simulation/model_engine.py), the sampled episodes every
policy is run in. The product state carried through the search is (road, true trust θ, spec DFA
state, projected DFA state, AV belief): the AV belief labels the belief atoms, so it is part
of the state a simulation must track. Rewards: 1 on the transition into an accepting DFA state,
0 otherwise; accepted and rejected states are absorbing. The rollout policy follows the
trust-free shortest completion (a random rollout almost never visits three waypoints in order).
Every random draw goes through the numpy Generator passed in (pomdp-py's UCB is deterministic).
The driver's draws in a simulated step are the synthetic driver's step
(participants/driver_step.py: takeover, the AV's performance, trust move), the draws of the
studies' driver and of the model engine.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pomdp_py

from trustroute.participants.driver_model import DriverTables
from trustroute.participants.driver_step import draw_rows, draw_step
from trustroute.policies.logic.compiled import CompiledSpec, compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.routing.episode_rules import dfa_verdict
from trustroute.policies.routing.free import StateOnlyTask, state_only_task
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

DEFAULT_NUM_SIMS = 200
DEFAULT_MAX_DEPTH = 20


class RoadAction(pomdp_py.Action):
    """Drive to the next junction; carries the directed road it leads to (hashable by it)."""

    def __init__(self, road: int, junction: str) -> None:
        self.road = road
        self.junction = junction

    def __hash__(self) -> int:
        return hash(self.road)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, RoadAction) and other.road == self.road

    def __repr__(self) -> str:
        return f"RoadAction({self.junction})"


class HumanObservation(pomdp_py.Observation):
    """(h, e) seen after driving a road; the incident is a function of the road, hence omitted."""

    def __init__(self, human_action: int, performance: int) -> None:
        self.key = (human_action, performance)

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, HumanObservation) and other.key == self.key


class ProductState(pomdp_py.State):
    """(road, θ index, DFA state, projected DFA state, AV belief, last observation, over)."""

    def __init__(self, road: int, theta: int, q: int, q_projected: int, belief: np.ndarray,
                 observation: tuple[int, int], over: bool) -> None:
        self.road = road
        self.theta = theta
        self.q = q
        self.q_projected = q_projected
        self.belief = belief
        self.observation = observation
        self.over = over

    def __hash__(self) -> int:
        return hash((self.road, self.theta, self.q, self.belief.tobytes()))

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, ProductState) and other.road == self.road and other.theta == self.theta
                and other.q == self.q and np.array_equal(other.belief, self.belief))


@dataclass(frozen=True, eq=False)
class ProductModel:
    """Everything the POUCT models need, precomputed once per (pomdp, spec, belief rule)."""

    pomdp: TrustPOMDP
    spec: Spec
    task: StateOnlyTask
    compiled: CompiledSpec
    actions: tuple[tuple[RoadAction, ...], ...]   # per road index
    driver: DriverTables                           # the true driver's tables (kind 0)
    belief_matrices: np.ndarray                    # [inc, h, e, θ, θ'] the AV filter's matrices

    def step(self, state: ProductState, action: RoadAction, rng: np.random.Generator) -> ProductState:
        if state.over:
            return state
        road = action.road
        inc = int(self.pomdp.road_incident[road])
        h, e, theta = draw_step(self.driver, 0, inc, state.theta, rng)
        unnormalised = state.belief @ self.belief_matrices[inc, h, e]
        total = unnormalised.sum()
        belief = unnormalised / total if total > 0 else unnormalised
        q = int(self.compiled.step(np.array([state.q]), np.array([road]), belief[None])[0])
        q_projected = int(self.task.next_state[state.q_projected, road])
        # Like a real episode without the fallback, a simulation goes on after the state-only task
        # is done (the planner may come back to a waypoint with more trust); it ends on acceptance
        # or rejection, or at the search depth.
        over = dfa_verdict(self.compiled, q) is not None
        return ProductState(road, theta, q, q_projected, belief, (h, e), over)


def build_product_model(pomdp: TrustPOMDP, spec: Spec, belief_rule: BeliefRule = "bayes") -> ProductModel:
    town, driver = pomdp.town, pomdp.driver
    compiled = compile_spec(spec, town)
    actions = tuple(
        tuple(RoadAction(town.state_index(town.successor(road, j)), j) for j in town.actions(road))
        for road in town.states)
    if belief_rule == "bayes":
        matrices = pomdp.weighted_transition
    elif belief_rule == "paper":
        matrices = driver.trust_transition
    else:
        raise ValueError(f"unknown belief rule {belief_rule!r}; use 'bayes' or 'paper'")
    return ProductModel(
        pomdp=pomdp, spec=spec, task=state_only_task(town, spec), compiled=compiled,
        actions=actions, driver=driver.tables, belief_matrices=np.asarray(matrices))


class _TransitionModel(pomdp_py.TransitionModel):
    def __init__(self, model: ProductModel, rng: np.random.Generator) -> None:
        self.model, self.rng = model, rng

    def sample(self, state, action):
        return self.model.step(state, action, self.rng)


class _ObservationModel(pomdp_py.ObservationModel):
    def sample(self, next_state, action):
        # The transition already drew (h, e) jointly with θ'; the observation just reports it.
        return HumanObservation(*next_state.observation)


class _RewardModel(pomdp_py.RewardModel):
    def __init__(self, model: ProductModel) -> None:
        self.model = model

    def sample(self, state, action, next_state):
        return float(not state.over and bool(self.model.compiled.accepting[next_state.q]))


class _PolicyModel(pomdp_py.RolloutPolicy):
    """Legal moves of the current road; rollouts follow the trust-free shortest completion."""

    def __init__(self, model: ProductModel, root_road: int) -> None:
        self.model, self.root_road = model, root_road

    def get_all_actions(self, state=None, history=None):
        if state is not None:
            road = state.road
        elif history:
            road = history[-1][0].road
        else:
            road = self.root_road
        return list(self.model.actions[road])

    def rollout(self, state, history=None):
        slot = int(self.model.task.next_slot[state.road, state.q_projected])
        return self.model.actions[state.road][max(slot, 0)]


class _TrustBelief(pomdp_py.GenerativeDistribution):
    """Root belief: known road, DFA states and AV belief; θ drawn from the true posterior."""

    def __init__(self, root: ProductState, posterior: np.ndarray, rng: np.random.Generator) -> None:
        self.root, self.cdf, self.rng = root, np.cumsum(posterior), rng

    def random(self):
        theta = draw_rows(self.cdf, self.rng)
        r = self.root
        return ProductState(r.road, theta, r.q, r.q_projected, r.belief, r.observation, r.over)

    def mpe(self):
        return self.random()


class POUCTPolicy(RoutingPolicy):
    """Plan each decision with pomdp-py's POUCT from the current belief ("pouct").

    Under the Bayes rule the AV's belief is the true posterior of θ, which is what the root
    samples; under the "paper" rule the AV's (unsound) belief is used for both, as an online
    planner on the AV would have nothing else.
    """

    name = "pouct"

    def __init__(self, model: ProductModel, rng: np.random.Generator, num_sims: int = DEFAULT_NUM_SIMS,
                 max_depth: int = DEFAULT_MAX_DEPTH, exploration_const: float = 1.0) -> None:
        self.model = model
        self.rng = rng
        self.num_sims = num_sims
        self.max_depth = max_depth
        self.exploration_const = exploration_const
        self.planning_seconds: list[float] = []

    def next_junction(self, context: DecisionContext) -> str:
        started = time.perf_counter()
        model = self.model
        town = model.pomdp.town
        road = town.state_index(context.road)
        q_projected = model.task.projected_state(context.route)
        belief = np.asarray(context.belief, dtype=float)
        root = ProductState(road, 0, int(context.dfa_state), q_projected, belief, (0, 0), False)
        agent = pomdp_py.Agent(_TrustBelief(root, belief, self.rng), _PolicyModel(model, road),
                               _TransitionModel(model, self.rng), _ObservationModel(),
                               _RewardModel(model))
        planner = pomdp_py.POUCT(max_depth=self.max_depth, planning_time=-1.0, num_sims=self.num_sims,
                                 discount_factor=1.0, exploration_const=self.exploration_const,
                                 rollout_policy=agent.policy_model)
        action = planner.plan(agent)
        self.planning_seconds.append(time.perf_counter() - started)
        return action.junction


def pouct_policy(pomdp: TrustPOMDP, spec: Spec, rng: np.random.Generator,
                 num_sims: int = DEFAULT_NUM_SIMS, max_depth: int = DEFAULT_MAX_DEPTH,
                 belief_rule: BeliefRule = "bayes") -> POUCTPolicy:
    return POUCTPolicy(build_product_model(pomdp, spec, belief_rule), rng, num_sims, max_depth)
