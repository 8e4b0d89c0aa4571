"""The gymnasium environment: the API checker on both engines, and a random agent against exact values."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env, data_equivalence

from trustroute.core.packaged import packaged_spec_names
from trustroute.harness.simulation.gym_env import ENV_ID, RUN_FACTS, TrustRoutingEnv
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.labelling import Labeller


def random_agent_end_probabilities(env: TrustRoutingEnv, agent=None) -> dict[str, float]:
    """Exact P(accepted), P(rejected), P(cap) of the uniformly random agent (over the legal junctions),
    or of the deterministic `agent` (an observation dict -> an action, read modulo the legal count).

    Computed here, independently of the environment's episode loop, by pushing probability mass
    forward through the belief MDP of the product: nodes (road, DFA state, belief) are merged when
    equal, each legal junction has probability 1/k (or the agent's has 1), each observation h its
    probability Σθ b(θ) P(h | θ, incident) under the Bayes belief (the exact posterior of the
    driver's trust).
    """
    from trustroute.policies.model.trust_pomdp import build_pomdp

    town, spec, cap = env.town, env.scldtl_spec, env.setup.junction_cap
    pomdp = build_pomdp(town, env.driver_model)
    dfa = build_dfa(spec)
    labeller = Labeller(spec, dfa, town)
    accepting, rejecting = np.asarray(dfa.accepting, bool), np.asarray(dfa.rejecting, bool)
    successors = np.asarray(pomdp.successor_table)
    degree = (successors >= 0).sum(axis=1)
    outcomes = [(h, e) for h in (0, 1) for e in ((0, 1) if env.driver_model.depends_on_performance else (0,))]
    road = np.array([town.state_index(spec.start)])
    belief = np.asarray(pomdp.initial_belief, float)[None, :]
    q = np.asarray(labeller.step(np.array([dfa.initial]), road, belief), dtype=np.int64)
    p = np.ones(1)
    mass = {"accepted": 0.0, "rejected": 0.0, "cap": 0.0}
    for level in range(cap + 1):
        acc, rej = accepting[q], rejecting[q] & ~accepting[q]
        mass["accepted"] += p[acc].sum()
        mass["rejected"] += p[rej].sum()
        live = ~(acc | rej)
        road, q, belief, p = road[live], q[live], belief[live], p[live]
        if level == cap:
            mass["cap"] += p.sum()
            break
        parts = []
        if agent is not None:   # the agent's slot of each node, its move taken with probability 1
            observations = ({"road": int(x), "dfa_state": int(d), "belief": b.copy(), "junctions": level}
                            for x, d, b in zip(road, q, belief, strict=True))
            chosen = np.array([agent(o) for o in observations], dtype=np.int64) % degree[road]
        for slot in range(successors.shape[1]):
            has = successors[road, slot] >= 0
            if agent is not None:
                has &= chosen == slot
            x2 = successors[road[has], slot]
            share = p[has] / degree[road[has]] if agent is None else p[has]
            for h, e in outcomes:
                post, p_obs = pomdp.belief_update(belief[has], pomdp.road_incident[x2], h, e)
                ok = p_obs > 0
                q2 = np.asarray(labeller.step(q[has][ok], x2[ok], post[ok]), dtype=np.int64)
                parts.append((x2[ok], q2, post[ok], share[ok] * p_obs[ok]))
        road, q, belief, p = (np.concatenate([part[i] for part in parts]) for i in range(4))
        keys = np.concatenate([road[:, None].astype(float), q[:, None].astype(float), belief], axis=1)
        unique, inverse = np.unique(keys, axis=0, return_inverse=True)
        p = np.bincount(inverse.ravel(), weights=p, minlength=len(unique))
        road, q, belief = unique[:, 0].astype(np.int64), unique[:, 1].astype(np.int64), unique[:, 2:]
    return mass


def test_registered_id_makes_the_environment():
    env = gymnasium.make(ENV_ID, spec="phi1", engine="model")
    assert isinstance(env.unwrapped, TrustRoutingEnv)
    observation, info = env.reset(seed=0)
    assert observation in env.observation_space
    assert info["action_mask"].sum() == len(info["legal_junctions"])
    env.close()


@pytest.mark.filterwarnings("ignore:.*render_mode='rgb_array' that is not in the possible")
def test_render_without_a_render_mode_renders_nothing():
    """gymnasium's rule for render_mode None: no render is computed, render() returns None."""
    env = gymnasium.make(ENV_ID, spec="phi1", engine="model")
    env.reset(seed=0)
    assert env.render_mode is None and env.metadata["render_modes"] == []
    assert env.render() is None
    with pytest.raises(ValueError, match="no render modes"):
        gymnasium.make(ENV_ID, spec="phi1", render_mode="rgb_array")
    env.close()


def test_check_env_model_engine():
    env = gymnasium.make(ENV_ID, spec="phi1", engine="model")
    check_env(env.unwrapped)
    env.close()


@pytest.mark.slow
def test_check_env_sumo_engine():
    env = gymnasium.make(ENV_ID, spec="phi1", engine="sumo")
    check_env(env.unwrapped)
    observation, info = env.reset(seed=5)
    for _ in range(3):   # a few SUMO roads, then reset mid-episode (the SUMO session must close)
        observation, reward, terminated, truncated, info = env.step(0)
        assert observation in env.observation_space and not truncated
        if terminated:
            break
    env.reset(seed=6)
    env.close()


ENGINES = ["model", "sumo"]  # both engines run check_env in well under a second per spec


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("spec", packaged_spec_names())
def test_check_env_every_packaged_spec(spec, engine):
    env = TrustRoutingEnv(spec, engine=engine)
    check_env(env)
    env.close()


def _run_to_the_end(env: TrustRoutingEnv, seed: int) -> dict:
    env.reset(seed=seed)
    done, step = False, 0
    while not done:
        _, _, terminated, truncated, info = env.step(step % 2)
        done, step = terminated or truncated, step + 1
    return info


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("spec", packaged_spec_names())
def test_last_step_info_is_a_function_of_seed_and_actions(spec, engine):
    env = TrustRoutingEnv(spec, engine=engine, junction_cap=6)
    first = _run_to_the_end(env, 3)
    first_run = env.unwrapped.last_run
    second = _run_to_the_end(env, 3)
    assert data_equivalence(first, second, exact=True)
    assert not set(RUN_FACTS) & set(first["summary"])
    # the run facts are kept beside: the counter, the episode id and the wall time
    assert (first_run["episode"], env.unwrapped.last_run["episode"]) == (1, 2)
    assert first_run["episode_id"] != env.unwrapped.last_run["episode_id"]
    assert env.unwrapped.last_run["wall_seconds"] >= 0
    assert ("sim_seconds" in first["summary"]) == (engine == "sumo")
    env.close()


def test_seeded_resets_repeat_and_differ():
    env = TrustRoutingEnv("phi1", engine="model", junction_cap=12)

    def rollout(seed: int) -> list:
        observation, info = env.reset(seed=seed)
        steps = [observation["belief"].tolist()]
        done = False
        while not done:
            observation, reward, terminated, truncated, info = env.step(1)
            steps.append((observation["road"], observation["dfa_state"], observation["belief"].tolist(),
                          reward))
            done = terminated or truncated
        return steps + [info["end_reason"]]

    assert rollout(7) == rollout(7)
    assert any(rollout(7) != rollout(s) for s in (8, 9, 10))
    env.close()


def test_ends_rewards_and_masks_follow_the_tracker():
    env = TrustRoutingEnv("phi1", engine="model", junction_cap=6)
    rng = np.random.default_rng(3)
    seen = set()
    for seed in range(40):
        observation, info = env.reset(seed=seed)
        done, steps = False, 0
        while not done:
            action = int(rng.integers(0, env.action_space.n))
            observation, reward, terminated, truncated, info = env.step(action)
            steps += 1
            done = terminated or truncated
            assert reward == (1.0 if terminated and info.get("end_reason") == "accepted" else 0.0)
        assert observation["junctions"] == steps == env.last_record.summary["junctions"]
        # the cap is the task's horizon: every end terminates, the cap's too (docs/gym_env.md)
        assert terminated and not truncated
        decided = info["end_reason"] in ("accepted", "rejected")
        assert (info["end_reason"] == "cap") == (steps == 6 and not decided)
        roads = env.last_record.roads   # the tracker's log: each action is the next road's end junction
        assert list(roads["action"].iloc[:-1]) == [r.split("-")[1] for r in roads["directed_road"].iloc[1:]]
        seen.add(info["end_reason"])
    assert seen == {"accepted", "cap"}
    with pytest.raises(RuntimeError, match="reset"):
        env.step(0)
    env.close()


@pytest.mark.slow
def test_random_agent_matches_exact_probabilities():
    # phi1_strict within 10 junctions: all three ends have sizeable mass (about 0.07, 0.30, 0.63).
    env = TrustRoutingEnv("phi1_strict", engine="model", junction_cap=10)
    exact = random_agent_end_probabilities(env)
    assert abs(sum(exact.values()) - 1) < 1e-9
    assert all(0.05 < p < 0.95 for p in exact.values())   # no end is (almost) sure: the test has teeth
    episodes = 2000
    counts = dict.fromkeys(exact, 0)
    env.action_space.seed(11)
    for i in range(episodes):
        observation, info = env.reset(seed=1000 + i)
        done = False
        while not done:
            action = env.action_space.sample(mask=info["action_mask"])
            observation, reward, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        counts[info["end_reason"]] += 1
    for reason, p in exact.items():
        estimate = counts[reason] / episodes
        se = max(np.sqrt(p * (1 - p) / episodes), 1e-12)
        assert abs(estimate - p) <= 4 * se, (reason, estimate, p, se)
    env.close()


def belief_agent(observation) -> int:
    """A deterministic agent that reads every part of the observation: the belief decides."""
    trusting = observation["belief"][-2:].sum() > 0.6
    return (observation["road"] + observation["dfa_state"] + observation["junctions"] + int(trusting)) % 2


@pytest.mark.slow
def test_an_agent_is_valued_exactly_as_the_environment_rewards_it():
    """evaluate_agent (trustroute.evaluate's unfolding of the agent as a routing policy) gives the
    agent's expected return: the forward propagation above computes it independently, and the
    environment's own episodes agree with it."""
    env = TrustRoutingEnv("phi1_strict", engine="model", junction_cap=10)
    exact = random_agent_end_probabilities(env, belief_agent)["accepted"]
    assert 0.05 < exact < 0.95   # the test has teeth
    value = env.evaluate_agent(belief_agent)
    assert value.lower <= exact + 1e-9 and exact - 1e-9 <= value.upper and value.upper - value.lower < 1e-9
    assert env.evaluate_agent(lambda observation: 1 - belief_agent(observation)).lower != value.lower
    episodes, rewards = 1000, 0.0
    for i in range(episodes):
        observation, info = env.reset(seed=3000 + i)
        done = False
        while not done:
            observation, reward, terminated, truncated, info = env.step(belief_agent(observation))
            done = terminated or truncated
        rewards += reward
    assert abs(rewards / episodes - exact) <= 4 * np.sqrt(exact * (1 - exact) / episodes)
    env.close()


def test_an_agents_value_under_a_node_budget_brackets_its_exact_value():
    """max_nodes bounds the unfolding as trustroute.evaluate's does: a wider certified bracket
    around the exact value; a bad budget is an InputError naming the keyword."""
    from trustroute.core.errors import InputError

    env = TrustRoutingEnv("phi1_strict", engine="model", junction_cap=10)
    exact = env.evaluate_agent(belief_agent)
    budget = env.evaluate_agent(belief_agent, max_nodes=20)
    assert exact.upper - exact.lower < 1e-9 and budget.upper - budget.lower > 0.01   # the budget bites
    assert budget.lower <= exact.lower and exact.upper <= budget.upper
    for bad in (0, "x"):
        with pytest.raises(InputError) as error:
            env.evaluate_agent(belief_agent, max_nodes=bad)
        assert str(error.value).startswith("max_nodes: "), error.value
    with pytest.raises(InputError, match="^time_limit: applies to specs with trust-state atoms only"):
        env.evaluate_agent(belief_agent, time_limit=5)


@pytest.mark.parametrize("population", [None, "driver_population_three_types"])
def test_an_agents_value_is_trustroute_evaluates_of_its_policy(population):
    """evaluate_agent is trustroute.evaluate's one door (trustroute/app/synthesis.py,
    `evaluate_problem`) with the environment's cap, belief rule and no fallback: equal values, for
    one driver model and over a population's mixture, and the population's refusal of a node
    budget in the environment's keywords."""
    import trustroute
    from trustroute.core.errors import InputError

    def agent(observation) -> int:
        return (observation["road"] + observation["junctions"]) % 2

    env = TrustRoutingEnv("phi1_strict", engine="model", junction_cap=10, belief_rule="paper",
                          population=population)
    value = env.evaluate_agent(agent)
    assert 0.05 < value.lower < 0.95   # the test has teeth
    api = trustroute.evaluate("phi1_strict", env.agent_policy(agent), population=population,
                              fallback_after=None, max_junctions=10, belief_rule="paper")
    untimed = [{k: v for k, v in found.to_dict().items() if k != "seconds"} for found in (value, api)]
    assert untimed[0] == untimed[1] and value.type_values == api.type_values
    if population is not None:
        with pytest.raises(InputError, match="^max_nodes: the pruning limits are not used"):
            env.evaluate_agent(agent, max_nodes=5)


def test_an_agent_as_a_routing_policy_drives_an_episode_as_step_does():
    """agent_policy: each junction run_episode drives is the agent's action on the observation the
    environment gives there (read off the episode's roads table), mapped as `step` maps it."""
    import trustroute

    env = TrustRoutingEnv("phi1_strict", engine="model")
    agent = env.agent_policy(belief_agent)
    roads = trustroute.run_episode("phi1_strict", agent, engine="model", seed=4).roads
    decided = roads[~roads["fallback"]].iloc[:-1]
    assert len(decided) > 3 and len(set(decided["action"])) > 1   # the test has teeth
    for junctions, row in decided.iterrows():
        observation = {"road": env.town.state_index(row["directed_road"]), "dfa_state": int(row["dfa_state"]),
                       "belief": np.asarray(row["belief_after"]), "junctions": int(junctions)}
        assert row["action"] == env.town.actions(row["directed_road"])[belief_agent(observation) % 2]
    with pytest.raises(ValueError, match="not in the action space"):
        env.junction_for("E-A", 2)


class FirstJunction:
    """Always the first legal junction: the agent of the population test, as a routing policy."""

    def __init__(self, town):
        from trustroute.policies.routing.protocol import RoutingPolicy

        class First(RoutingPolicy):
            name = "first"

            def next_junction(self, context):
                return town.actions(context.road)[0]

        self.policy = First()


@pytest.mark.slow
def test_population_with_a_trust_state_spec_matches_exact_per_type_values(driver):
    from tests.policies.trust_state_synthesis.test_population import random_population_problem
    from trustroute.policies.belief.driver_types import trust_marginal
    from trustroute.policies.evaluation.trust_state import evaluate_joint_by_type
    from trustroute.policies.model.trust_pomdp import build_pomdp

    town, population, spec = random_population_problem(np.random.default_rng(0), driver, 3, "trust")
    env = TrustRoutingEnv(spec, town=town, population=population, junction_cap=6)
    assert spec.uses_trust_atoms and env.observation_space["belief"].shape == (3 * 7,)
    check_env(env, skip_render_check=True)
    exact, per_type = evaluate_joint_by_type(build_pomdp(town, env.driver_model), env.scldtl_spec,
                                             FirstJunction(town).policy,
                                             EvaluationSettings(fallback_after=None, max_junctions=6))
    assert exact.gap == 0 and 0.05 < exact.lower < 0.95    # the test has teeth
    episodes = 1500
    ends = {name: [] for name in population.names}
    for i in range(episodes):
        observation, info = env.reset(seed=2000 + i)
        done = False
        while not done:
            observation, reward, terminated, truncated, info = env.step(0)
            done = terminated or truncated
        ends[env.driver_type].append(reward)
        assert observation["belief"].shape == (21,)
        # the logged Arrow table's last belief, read without a pandas frame of every episode
        last_belief = env.unwrapped.last_record.tables()["roads"].column("belief_after")[-1].as_py()
        assert np.allclose(trust_marginal(env.driver_model, observation["belief"]), last_belief,
                           atol=1e-12)
    rewards = [r for rs in ends.values() for r in rs]
    se = np.sqrt(exact.lower * (1 - exact.lower) / episodes)
    assert abs(np.mean(rewards) - exact.lower) <= 4 * se
    for (name, got), (value, _), weight in zip(ends.items(), per_type, population.weights, strict=True):
        assert abs(len(got) / episodes - weight) <= 4 * np.sqrt(weight * (1 - weight) / episodes), name
        assert abs(np.mean(got) - value) <= 4 * max(np.sqrt(value * (1 - value) / len(got)), 1e-12), name
    env.close()


def _to_the_end(env, seed):
    _, info = env.reset(seed=seed)
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(0)
        done = terminated or truncated
    return info["summary"]


def test_a_second_sumo_episode_in_one_process_is_refused_and_sequential_ones_run():
    import gc

    import trustroute
    from trustroute.harness.simulation.sumo_start import SimulationInUse

    first, second = (TrustRoutingEnv("phi1", engine="sumo") for _ in range(2))
    alone = _to_the_end(first, 5)
    first.reset(seed=5)
    with pytest.raises(SimulationInUse, match="one SUMO simulation per process.*AsyncVectorEnv"):
        second.reset(seed=6)
    with pytest.raises(SimulationInUse):
        trustroute.run_episode("phi1", engine="sumo", seed=1)
    done = False
    while not done:   # the running episode is untouched by the refused ones
        _, _, terminated, truncated, info = first.step(0)
        done = terminated or truncated
    assert data_equivalence(info["summary"], alone)
    assert data_equivalence(_to_the_end(second, 5), alone)   # once it has ended, the next one runs
    first.reset(seed=5)
    first.close()                                             # closed mid-episode
    assert data_equivalence(_to_the_end(second, 5), alone)
    first.reset(seed=5)
    del first                                                 # dropped mid-episode
    gc.collect()
    assert data_equivalence(_to_the_end(second, 5), alone)
    second.close()


@pytest.mark.parametrize("action", [5, -1, 1.7, "1", True, np.array([1]), None, "x"])
def test_an_action_outside_the_action_space_is_refused_and_the_episode_goes_on(action):
    env, twin = TrustRoutingEnv("phi1"), TrustRoutingEnv("phi1")
    env.reset(seed=3)
    twin.reset(seed=3)
    refused = r"not in the action space Discrete\(2\): pass an integer from 0 to 1"
    with pytest.raises(ValueError, match=refused):
        env.step(action)
    assert data_equivalence(env.step(np.int64(1)), twin.step(1))


@pytest.mark.parametrize(("field", "value", "problem"), [
    ("belief_rule", "foo", "unknown belief rule 'foo'"),
    ("report_accuracy", 2.0, "2.0 is not a probability"),
    ("report_accuracy", -0.5, "-0.5 is not a probability"),
    ("junction_cap", 2.5, "expected an integer from 1 to 10000, got 2.5"),
    ("junction_cap", "10", "expected an integer from 1 to 10000, got '10'"),
    ("junction_cap", 0, "expected an integer from 1 to 10000, got 0"),
    ("engine", "live", "unknown engine 'live'"),
    ("net_path", 5, "expected a file path, got 5"),
])
def test_every_env_setting_is_checked_when_made(field, value, problem):
    from trustroute.core.errors import InputError
    from trustroute.harness.simulation.gym_env import EnvSettings

    with pytest.raises(InputError, match=problem) as made:
        EnvSettings(**{field: value})
    with pytest.raises(InputError, match=problem) as through_make:   # before any episode
        gymnasium.make(ENV_ID, spec="phi1", **{field: value})
    # every field's refusal has one form: the settings object, then the field
    for error in (made.value, through_make.value):
        assert str(error).startswith(f"EnvSettings: {field}: "), error


def test_a_net_on_the_model_engine_is_refused_not_ignored(tmp_path):
    """net_path is the SUMO engine's net (docs/gym_env.md): the model engine would drive without
    reading it, so it is one InputError naming the field, as an unknown engine is."""
    from trustroute.core.errors import InputError
    from trustroute.harness.simulation.gym_env import EnvSettings

    net = tmp_path / "town.net.xml"
    said = ("EnvSettings: net_path: a SUMO net needs the SUMO engine, not 'model' (fix: run on the SUMO "
            "engine (engine 'sumo') or drop net_path)")
    for make in (lambda: EnvSettings(net_path=net), lambda: gymnasium.make(ENV_ID, spec="phi1", net_path=net),
                 lambda: TrustRoutingEnv("phi1", settings=EnvSettings(engine="sumo", net_path=net),
                                         engine="model")):
        with pytest.raises(InputError) as error:
            make()
        assert error.value.one_line() == said
    assert EnvSettings(engine="sumo", net_path=net).net_path == net   # the SUMO engine reads it


@pytest.mark.parametrize(("argument", "value", "said"), [
    ("town", "city5", "pass an existing town file as town or a packaged town name"),
    ("driver", "no_such_driver.json", "pass an existing driver model file as driver or a packaged"),
])
def test_a_bad_input_is_said_in_the_environments_keywords_not_the_cli_flags(argument, value, said):
    """gymnasium.make is a door of the Python API: its errors name `town=`, as trustroute.load_town's do."""
    from trustroute.core.errors import InputError

    with pytest.raises(InputError) as error:
        gymnasium.make(ENV_ID, spec="phi1", **{argument: value})
    assert said in str(error.value) and "--" not in str(error.value), error.value


def test_a_driver_and_a_population_together_are_refused_as_the_api_refuses_them():
    """The one check of the inputs (trustroute/app/inputs.py): an InputError naming `population`,
    as `trustroute.run_episode(driver=..., population=...)` gives it, not a ValueError of its own."""
    from trustroute.core.errors import InputError

    with pytest.raises(InputError) as error:
        gymnasium.make(ENV_ID, spec="phi1", driver="driver_model", population="driver_population_three_types")
    assert str(error.value).startswith("population: a driver model and a driver population were both given")
    assert "--" not in str(error.value), error.value


def test_env_settings_read_the_shared_defaults():
    from trustroute.core import defaults
    from trustroute.harness.simulation.gym_env import EnvSettings

    settings = EnvSettings()
    assert (settings.engine, settings.belief_rule, settings.junction_cap) == (
        defaults.GYM_ENGINE, defaults.BELIEF_RULE, defaults.JUNCTION_CAP)


@pytest.mark.parametrize("formula", ["F v1", "!v1 U v2"])
def test_a_spec_decided_on_its_start_road_is_refused_when_made(tmp_path, formula):
    """An episode with no junction to choose cannot give reset an observation: the spec is bad input
    for the environment, one InputError naming its file when it is made, before any episode."""
    from trustroute.core.errors import InputError

    path = tmp_path / "decided.toml"
    path.write_text(f'name = "decided"\nstart = "E-A"\nformula = "{formula}"\n\n'
                    '[states]\nv1 = ["E-A"]\nv2 = ["A-F"]\n')
    with pytest.raises(InputError) as error:
        gymnasium.make(ENV_ID, spec=str(path))
    said = str(error.value)
    assert said.startswith(f"{path}: start: ") and "decided on its start road" in said, said
    assert ("accepted" if formula.startswith("F") else "rejected") in said


# An episode (phi1_trust, the three-type population, seed 1) whose 46th road is D-E with an unseen
# oncoming truck: the ego, pulled out beside the obstacle, and the truck met nose to nose.
HEAD_ON_ACTIONS = (1, 1, 0, 0, 0, 1, 0, 1, 1, 0, 0, 1, 0, 1, 1, 0, 1, 1, 1, 0, 0, 1, 1, 0, 1, 1, 1, 0,
                   1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 0, 0, 0, 0, 0, 0, 0)


@pytest.mark.slow
def test_a_head_on_standstill_with_the_oncoming_truck_ends_with_the_truck_backing_off():
    """Neither can move (SUMO drives no vehicle backwards): the truck backs off, out of the
    simulation, and the episode goes on instead of standing until the sim-time cap."""
    env = TrustRoutingEnv("phi1_trust", engine="sumo", population="driver_population_three_types")
    _, info = env.reset(seed=1)
    done = False
    for action in (*HEAD_ON_ACTIONS, *[0] * env.setup.junction_cap):   # then on to the end
        _, _, terminated, truncated, info = env.step(action)
        if done := terminated or truncated:
            break
    assert done
    incidents = env.last_record.incidents
    roads = env.last_record.roads
    backed = incidents[incidents["scene"].str.contains("backed_off=yes", na=False)]
    assert backed["directed_road"].tolist() == ["D-E"], incidents[["directed_road", "scene"]]
    assert backed["performance"].tolist() == ["fail"]
    assert roads.loc[backed["index"].iloc[0], "directed_road"] == "D-E"
    assert info["summary"]["sim_seconds"] < 1000
    env.close()


def test_a_reward_read_at_the_cap_ends_the_task_there():
    """A spec on the hidden trust is read at the cap: an episode rewarded there is terminated, not
    truncated, as is every episode the cap ends (the cap is the task's horizon, docs/gym_env.md)."""
    env = TrustRoutingEnv("phi1_trust", engine="model", junction_cap=8)
    rng = np.random.default_rng(11)
    rewarded_at_cap = 0
    for seed in range(30):
        env.reset(seed=seed)
        terminated = truncated = False
        while not (terminated or truncated):
            _, reward, terminated, truncated, info = env.step(int(rng.integers(0, env.action_space.n)))
        assert terminated and not truncated, info["end_reason"]
        rewarded_at_cap += info["end_reason"] == "cap" and reward == 1.0
    assert rewarded_at_cap > 0   # the case the rule is for occurred
