"""The gym environment's cost against the plain episode it wraps, on both engines.

`TrustRoutingEnv` steps the project's own episode objects (harness/simulation/stepping.py): each
`step` answers a decision point with `choose` and runs `advance` to the next. The baseline is the
same episode run without the environment: `run_to_end` on the same episode class with the same
setup, a routing policy that makes the agent's choices, and a synthetic driver drawn as `reset`
draws it from the same seed, so both sides drive the same roads with the same draws (checked
first, episode by episode). What the target adds is the environment's own work: the action
checked and mapped to a junction, the observation and info built at each step, the summary and
the final belief at the end.

The agent alternates by the junction count of its observation; phi1 on the packaged town. Each
timed call runs a batch of seeded episodes; target and baseline run in interleaved pairs in this
process (benchmarks/timing.py `paired_ratio`: median of the per-pair ratios, in wall and CPU
time, with the load average). The SUMO sides run one after another in one process, each episode
returning the simulation the process keeps open to its empty state, as a study's worker does.
"""

from __future__ import annotations

import math

import numpy as np

from benchmarks.timing import paired_ratio
from trustroute.app.drivers import synthetic_driver
from trustroute.harness.simulation.episode_record import EpisodeRecord
from trustroute.harness.simulation.gym_env import RUN_FACTS, TrustRoutingEnv
from trustroute.harness.simulation.stepping import SteppableEpisode, run_to_end
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

SPEC = "phi1"
RUNS = {"model": (20, 31), "sumo": (5, 11)}   # engine -> (episodes per timed call, pairs)
SEED_DRAW = 2**31 - 1   # reset draws its SUMO seed in [0, SEED_DRAW) before the driver


def agent(observation: dict) -> int:
    """The agent of the gym side: the first and the second legal junction by turns."""
    return observation["junctions"] % 2


class Alternating(RoutingPolicy):
    """The agent's choices as a plain routing policy (action a is legal junction a mod k)."""

    name = "agent"

    def __init__(self, env: TrustRoutingEnv) -> None:
        self.town = env.town

    def next_junction(self, context: DecisionContext) -> str:
        legal = self.town.actions(context.road)
        return legal[(context.junctions_driven % 2) % len(legal)]


def gym_episode(env: TrustRoutingEnv, seed: int) -> int:
    """One episode through the environment's API; the steps taken."""
    observation, _ = env.reset(seed=seed)
    steps, done = 0, False
    while not done:
        observation, _, terminated, truncated, _ = env.step(agent(observation))
        steps, done = steps + 1, terminated or truncated
    return steps


def plain_episode(env: TrustRoutingEnv, seed: int) -> EpisodeRecord:
    """The same episode without the environment: its driver drawn as `reset` draws it."""
    rng = np.random.default_rng(seed)
    sumo_seed = int(rng.integers(0, SEED_DRAW))
    driver = synthetic_driver(env.driver_model, rng, report_accuracy=env.report_accuracy)
    episode: SteppableEpisode
    if env.engine == "model":
        from trustroute.harness.simulation.model_engine import ModelEpisode

        episode = ModelEpisode(env.setup, Alternating(env), driver, f"plain-{seed}", sumo_seed)
    else:
        from trustroute.harness.simulation.episode import EpisodeOptions, SumoEpisode

        episode = SumoEpisode(env.setup, Alternating(env), driver, f"plain-{seed}", sumo_seed,
                              EpisodeOptions(net_path=env.net_path))
    return run_to_end(episode)


def _facts(record: EpisodeRecord) -> dict:
    """An episode's summary without what differs between two runs of it (NaN read as None)."""
    return {key: None if isinstance(value, float) and math.isnan(value) else value
            for key, value in record.summary.items() if key not in (*RUN_FACTS, "episode_id")}


def check_same_episodes(env: TrustRoutingEnv, seeds: range) -> int:
    """The steps of the batch; AssertionError when an episode differs between the two sides."""
    steps = 0
    for seed in seeds:
        steps += gym_episode(env, seed)
        assert env.last_record is not None
        gym_side, plain = _facts(env.last_record), _facts(plain_episode(env, seed))
        if gym_side != plain:
            raise AssertionError(f"seed {seed}: the environment's episode {gym_side} is not the plain "
                                 f"one {plain}")
    return steps


def measure(engine: str) -> dict:
    episodes, pairs = RUNS[engine]
    env = TrustRoutingEnv(SPEC, engine=engine)
    seeds = range(episodes)
    steps = check_same_episodes(env, seeds)   # also warms both paths (SUMO started, tables built)

    def target() -> None:
        for seed in seeds:
            gym_episode(env, seed)

    def baseline() -> None:
        for seed in seeds:
            plain_episode(env, seed)

    paired = paired_ratio(target, baseline, pairs=pairs)
    env.close()
    return {
        "name": f"gym_{engine}_{SPEC}_per_step", "value": paired["target_wall_median"] / steps, "unit": "s",
        "baseline": paired["baseline_wall_median"] / steps, "ratio": paired["wall_ratio_median"],
        "cpu_ratio": paired["cpu_ratio_median"],
        "ratio_what": f"median of {pairs} interleaved (environment, plain episode) pairs, wall and CPU "
                      f"time, each a batch of {episodes} seeded episodes ({steps} steps); no target",
        "episodes": episodes, "steps": steps,
        **{key: value for key, value in paired.items() if not key.endswith("ratio_median")},
    }


def run() -> list[dict]:
    return [measure(engine) for engine in RUNS]
