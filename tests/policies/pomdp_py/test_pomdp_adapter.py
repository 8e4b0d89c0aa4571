"""The pomdp-py adapter against the trust POMDP it wraps.

A pomdp-py simulated step (pomdp_py.sample_generative_model) is tested against the model's
joint probabilities of (h, e, θ') with a chi-square test at a fixed seed (and shown to reject
the wrong trust row); pomdp-py's exact histogram update is compared with the Bayes filter;
particles approach it; POUCT plans on the result.
"""

from __future__ import annotations

import numpy as np
import pomdp_py
import pytest

from tests.participants.test_synthetic_driver import chi_square_p
from tests.policies.model.test_trust_pomdp import random_model
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.pomdp_py.adapter import (
    RouteAction,
    RouteObservation,
    RouteState,
    build_models,
    build_problem,
    initial_belief,
    trust_marginal,
    update_belief,
)

ALPHA = 1e-4


@pytest.fixture(scope="module")
def failing_pomdp(town):
    """A random model with AV failures, so that all four (h, e) outcomes occur."""
    return build_pomdp(town, random_model(np.random.default_rng(12), 7, performance_dependent=True,
                                          sparse=False))


@pytest.mark.parametrize("start, junction, trust", [("E-A", "B", 3), ("A-F", "G", 0), ("H-L", "K", 6)])
def test_simulated_step_matches_the_model(failing_pomdp, start, junction, trust):
    pomdp = failing_pomdp
    rng = np.random.default_rng(31 + trust)
    problem, task = build_problem(pomdp, start, ["K-J"], rng)
    state = RouteState(pomdp.town.state_index(start), trust)
    action = RouteAction(junction)
    road = pomdp.town.state_index(pomdp.town.successor(start, junction))
    inc = int(pomdp.road_incident[road])
    n = 20000
    counts = np.zeros((2, 2, 7))
    for _ in range(n):
        next_state, observation, reward, steps = pomdp_py.sample_generative_model(problem.agent, state,
                                                                                  action)
        assert next_state.road == road and steps == 1 and reward == 0.0
        assert observation == RouteObservation(inc, next_state.human_action, next_state.performance)
        counts[next_state.human_action, next_state.performance, next_state.trust] += 1
    expected = pomdp.weighted_transition[inc, :, :, trust, :]          # P(h, e, θ' | θ, inc)
    assert expected.sum() == pytest.approx(1.0)
    assert chi_square_p(counts.ravel(), expected.ravel()) > ALPHA
    wrong_trust = trust + 1 if trust < 6 else trust - 1
    assert chi_square_p(counts.ravel(), pomdp.weighted_transition[inc, :, :, wrong_trust, :].ravel()) < ALPHA
    # the explicit probabilities agree with the arrays and sum to one over all states
    transition = problem.agent.transition_model
    total = sum(transition.probability(s, state, action) for s in transition.get_all_states())
    assert total == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_histogram_update_is_the_bayes_filter(town, seed):
    rng = np.random.default_rng(seed)
    pomdp = build_pomdp(town, random_model(rng, 7, performance_dependent=True, sparse=False))
    task, transition, observation_model, _, policy = build_models(pomdp, [], rng)
    road = town.state_index("E-A")
    belief = initial_belief(pomdp, road, rng)
    exact = pomdp.initial_belief.copy()
    state = RouteState(road, int(rng.integers(7)))
    for _ in range(6):
        action = policy.sample(state)
        state = transition.sample(state, action)
        obs = observation_model.sample(state, action)
        belief = update_belief(belief, task, action, obs, rng)
        exact = pomdp.belief_update(exact, obs.incident, obs.human_action, obs.performance)[0][0]
        assert np.allclose(trust_marginal(belief, 7), exact, rtol=1e-9, atol=1e-12)
        assert {s.road for s in belief.histogram} == {state.road}


def test_particle_update_approaches_the_bayes_filter(failing_pomdp):
    pomdp = failing_pomdp
    rng = np.random.default_rng(5)
    task, _, _, _, _ = build_models(pomdp, [], rng)
    road = pomdp.town.state_index("E-A")
    n = 20000
    particles = initial_belief(pomdp, road, rng, kind="particles", n_particles=n)
    action = RouteAction("B")
    inc = int(pomdp.road_incident[pomdp.town.state_index("A-B")])
    obs = RouteObservation(inc, 1, 1)
    exact = pomdp.belief_update(pomdp.initial_belief, inc, 1, 1)[0][0]
    updated = update_belief(particles, task, action, obs, rng)
    marginal = trust_marginal(updated, 7)
    # initial draw, resampling and moving each add multinomial noise: allow 3x the variance
    bound = 5 * np.sqrt(3 * exact * (1 - exact) / n) + 1e-9
    assert (np.abs(marginal - exact) <= bound).all()
    assert all(s.human_action == 1 and s.performance == 1 for s in updated.particles)
    with pytest.raises(ValueError, match="probability 0"):
        update_belief(particles, task, action, RouteObservation((inc + 1) % 4, 0, 0), rng)


def test_reward_on_first_reaching_a_target_then_absorbing(pomdp):
    rng = np.random.default_rng(0)
    task, transition, _, reward, policy = build_models(pomdp, ["A-B"], rng)
    start = RouteState(pomdp.town.state_index("E-A"), 3)
    target = transition.sample(start, RouteAction("B"))
    assert pomdp.town.states[target.road] == "A-B"
    assert reward.sample(start, RouteAction("B"), target) == 1.0
    other = transition.sample(start, RouteAction("F"))
    assert reward.sample(start, RouteAction("F"), other) == 0.0
    for action in policy.get_all_actions(target):
        assert transition.sample(target, action) == target
        assert transition.probability(target, target, action) == 1.0
        assert reward.sample(target, action, target) == 0.0
    with pytest.raises(ValueError, match="not a directed road"):
        build_models(pomdp, ["A-K"], rng)


def test_policy_model_offers_the_legal_moves(pomdp):
    rng = np.random.default_rng(0)
    _, transition, _, _, policy = build_models(pomdp, [], rng)
    for x, road in enumerate(pomdp.town.states):
        state = RouteState(x, 0)
        actions = policy.get_all_actions(state)
        assert [a.junction for a in actions] == list(pomdp.town.actions(road))
        assert sum(policy.probability(a, state) for a in actions) == pytest.approx(1.0)
        assert policy.sample(state) in actions
    with pytest.raises(ValueError, match="not a legal move"):
        transition.sample(RouteState(pomdp.town.state_index("E-A"), 0), RouteAction("E"))


def test_pouct_plans_the_immediate_reward(pomdp):
    """From E-A the target A-B is one move away via B; any other move needs three more."""
    rng = np.random.default_rng(3)
    problem, _ = build_problem(pomdp, "E-A", ["A-B"], rng, true_trust=4)
    planner = pomdp_py.POUCT(max_depth=4, planning_time=-1.0, num_sims=200, discount_factor=0.9,
                             exploration_const=1.0, rollout_policy=problem.agent.policy_model)
    assert planner.plan(problem.agent) == RouteAction("B")


@pytest.mark.parametrize("kind", ["histogram", "particles"])
def test_pouct_episode_runs_and_is_reproducible(pomdp, kind):
    def episode(seed: int) -> list:
        rng = np.random.default_rng(seed)
        problem, task = build_problem(pomdp, "E-A", ["K-L", "E-L", "H-L"], rng, belief=kind,
                                      n_particles=300)
        planner = pomdp_py.POUCT(max_depth=8, planning_time=-1.0, num_sims=150, discount_factor=0.95,
                                 exploration_const=1.0, rollout_policy=problem.agent.policy_model)
        trace = []
        for _ in range(12):
            action = planner.plan(problem.agent)
            assert action.junction in pomdp.town.actions(pomdp.town.states[problem.env.state.road])
            reward = problem.env.state_transition(action, execute=True)
            observation = problem.agent.observation_model.sample(problem.env.state, action)
            problem.agent.set_belief(update_belief(problem.agent.belief, task, action, observation, rng))
            planner.update(problem.agent, action, observation)
            trace.append((action.junction, observation, reward))
            if reward:
                break
        return trace

    first = episode(9)
    assert first == episode(9)
    assert first[-1][2] == 1.0          # reached the target within 12 moves
