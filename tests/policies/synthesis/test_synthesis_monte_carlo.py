"""(b) 10^5 simulated episodes of the synthesized policy agree with its certified value.

The simulation samples the hidden trust path from the driver model (θ0 from the initial belief,
takeovers and failures from θ, θ' from the trust dynamics) and runs the AV's Bayes filter on what
it sees, all vectorised over episodes; it shares with the solver only the model arrays, the labeller
and the policy's own decision function.
"""

from __future__ import annotations

import numpy as np
import pytest

from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.free import state_only_task
from trustroute.policies.routing.protocol import DecisionContext
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.settings import SynthesisSettings

EPISODES = 100_000
HORIZON = 20


def draw(cdf: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One index per row of a row-wise cumulative distribution."""
    u = rng.random(cdf.shape[0])[:, None] * cdf[:, -1:]
    return np.minimum((cdf <= u).sum(axis=1), cdf.shape[1] - 1)


def simulate_policy(pomdp, spec, policy, episodes, horizon, rng, check_scalar=0):
    """Satisfied-within-horizon flags, vectorised over episodes. check_scalar: for that many
    episodes, also ask the policy's scalar rule (next_junction on the real route) at every step
    and assert that it agrees with the vectorised one."""
    town, driver = pomdp.town, pomdp.driver
    dfa = build_dfa(spec)
    labeller = Labeller(spec, dfa, town)
    task = state_only_task(town, spec)
    theta = draw(np.broadcast_to(np.cumsum(driver.initial_belief), (episodes, driver.n_trust)), rng)
    belief = np.tile(np.asarray(driver.initial_belief, dtype=float), (episodes, 1))
    x = np.full(episodes, town.state_index(spec.start))
    projected = np.full(episodes, task.initial_state)
    routes = [[spec.start] for _ in range(min(check_scalar, episodes))]
    q = np.asarray(labeller.step(np.full(episodes, dfa.initial), x, belief), dtype=np.int64)
    satisfied = np.asarray(dfa.accepting, dtype=bool)[q].copy()
    alive = ~satisfied & ~np.asarray(dfa.rejecting, dtype=bool)[q]
    transition_cdf = np.cumsum(driver.trust_transition, axis=-1)
    for t in range(horizon):
        live = np.flatnonzero(alive)
        if live.size == 0:
            break
        slot = policy.action_slots(np.full(live.size, t), x[live], q[live], belief[live],
                                   projected=projected[live])
        for i in np.flatnonzero(live < len(routes)):
            n = live[i]
            context = DecisionContext(route=tuple(routes[n]), dfa_state=int(q[n]), belief=belief[n])
            assert policy.next_junction(context) == town.actions(town.states[x[n]])[slot[i]]
        x2 = pomdp.successor_table[x[live], slot]
        for i in np.flatnonzero(live < len(routes)):
            routes[live[i]].append(town.states[x2[i]])
        incident = pomdp.road_incident[x2]
        th = theta[live]
        h = (rng.random(live.size) < driver.takeover_probability[incident, th]).astype(np.int64)
        e = (rng.random(live.size) < driver.failure_probability[incident, th]).astype(np.int64)
        theta[live] = draw(transition_cdf[incident, h, e, th], rng)
        belief[live] = pomdp.belief_update(belief[live], incident, h, e)[0]
        x[live] = x2
        projected[live] = task.next_state[projected[live], x2]
        q[live] = labeller.step(q[live], x2, belief[live])
        accepted = np.asarray(dfa.accepting, dtype=bool)[q[live]]
        satisfied[live[accepted]] = True
        alive[live[accepted | np.asarray(dfa.rejecting, dtype=bool)[q[live]]]] = False
    return satisfied


@pytest.mark.slow
@pytest.mark.parametrize("name", ["phi1", "phi2"])
def test_monte_carlo_agrees_with_the_certified_value(pomdp, name):
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-3, horizon=HORIZON))
    satisfied = simulate_policy(pomdp, spec, result.policy, EPISODES, HORIZON, np.random.default_rng(5))
    rate = satisfied.mean()
    se = max(np.sqrt(rate * (1 - rate) / EPISODES), 1.0 / EPISODES)
    # The policy's value lies in [lower, upper]; the simulation estimates it.
    assert result.lower - 4 * se <= rate <= result.upper + 4 * se, (rate, result.lower, result.upper, se)
    # and agrees with the exact value of the same policy computed by the independent evaluator.
    exact = evaluate(pomdp, spec, result.policy,
                     EvaluationSettings(fallback_after=None, max_junctions=HORIZON))
    assert abs(rate - exact.lower) <= 4 * se + exact.gap, (rate, exact.lower, se)


def test_vectorised_and_scalar_decisions_agree(pomdp):
    """On the vehicle's real routes and beliefs the scalar rule (next_junction, which derives the
    state-only task state from the route) and the vectorised one agree; a stored belief gives its
    row's action, a belief 1e-3 away the trust-free completion's move."""
    spec = load_spec("specs/phi2.toml", pomdp.town)
    policy = synthesize(pomdp, spec, SynthesisSettings(horizon=10)).policy
    simulate_policy(pomdp, spec, policy, 300, 10, np.random.default_rng(2), check_scalar=300)
    table = policy.table
    exact = policy.action_slots(table.t, table.x, table.q, table.beliefs, projected=table.projected)
    assert (exact == table.action).all()
    rng = np.random.default_rng(3)
    moved = table.beliefs + rng.normal(0, 1e-3, size=table.beliefs.shape)
    slots = policy.action_slots(table.t, table.x, table.q, moved, projected=table.projected)
    task = state_only_task(pomdp.town, spec)
    completion = task.next_slot[table.x, table.projected]
    free = np.where(completion >= 0, completion, 0)
    assert (slots == free).all()
