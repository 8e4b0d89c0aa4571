"""Study throughput: the model engine, the study runner, and paper-size / large studies in SUMO.

- model engine, vectorised batch path (simulate_batch) on φ1 with the trust-free and the aware
  policy, episodes per minute (target >= 100k), against the per-episode path (EpisodeTracker +
  SyntheticDriver, one episode at a time) as the baseline;
- the study runner on the model engine with per-episode Parquet parts (1000 participants =
  4000 episodes, 2 workers), episodes per minute end to end;
- the paper-size study in SUMO (21 participants = 84 episodes, 2 workers; target <= 60 s) and a
  4000-episode SUMO study with 2 workers (target <= 15 min) against bare libsumo loops driving
  its very routes (throughput ratio, target <= 2), when the SUMO engine is installed.
Studies run in a temporary directory; synthesized policies come from the usual policy cache.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.bench_episode import study_against_bare
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.model_engine import run_model_episode, simulate_batch
from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.resolve import resolve_policy
from trustroute.policies.routing.free import trust_free_policy

BATCH_EPISODES = 100_000
SINGLE_EPISODES = 500
RUNNER_PARTICIPANTS = 1000
SUMO_LARGE_PARTICIPANTS = 1000
WORKERS = 2


def _study(participants: int, engine: str, out: Path) -> tuple[float, object]:
    from trustroute.harness.study.config import study_config_from_dict
    from trustroute.harness.study.runner import run_and_consolidate

    config = study_config_from_dict(
        {
            "study": {
                "name": f"bench-{engine}-{participants}",
                "participants": participants,
                "seed": 1,
                "engine": engine,
                "specs": ["phi1", "phi2"],
                "conditions": ["aware", "free"],
            }
        },
        "bench_study",
        Path.cwd(),
    )
    started = time.perf_counter()
    run, _ = run_and_consolidate(config, out, WORKERS, None, progress=False, echo=lambda *_: None)
    return time.perf_counter() - started, run


def run() -> list[dict]:
    town, driver = load_town(), load_driver_model()
    spec = load_spec("specs/phi1.toml", town)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec)
    results: list[dict] = []
    policies = {"free": trust_free_policy(town, spec), "aware": resolve_policy("aware", town, driver, spec)}
    for name, policy in policies.items():
        rng = np.random.default_rng(1)
        started = time.perf_counter()
        for i in range(SINGLE_EPISODES):
            run_model_episode(setup, policy, SyntheticDriver(driver, rng), f"e{i}", 0)
        single = SINGLE_EPISODES / (time.perf_counter() - started) * 60
        simulate_batch(setup, policy, 1000, np.random.default_rng(0))  # warm caches
        started = time.perf_counter()
        batch = simulate_batch(setup, policy, BATCH_EPISODES, np.random.default_rng(2))
        seconds = time.perf_counter() - started
        per_minute = BATCH_EPISODES / seconds * 60
        results.append(
            {
                "name": f"study.model_engine.batch.{name}.episodes_per_minute",
                "value": per_minute,
                "unit": "episodes/min",
                "baseline": single,
                "ratio": per_minute / single,
                "baseline_what": f"per-episode path (EpisodeTracker), {SINGLE_EPISODES} episodes",
                "target": 100_000,
                "episodes": BATCH_EPISODES,
                "seconds": seconds,
                "satisfaction": float(batch.satisfied.mean()),
                "policy_calls": batch.policy_calls,
            }
        )

    with tempfile.TemporaryDirectory(prefix="trustroute-bench-") as folder:
        seconds, run_info = _study(RUNNER_PARTICIPANTS, "model", Path(folder) / "model")
        episodes = RUNNER_PARTICIPANTS * 4
        results.append(
            {
                "name": "study.runner.model_engine.episodes_per_minute",
                "value": episodes / seconds * 60,
                "unit": "episodes/min",
                "episodes": episodes,
                "seconds": seconds,
                "workers": WORKERS,
                "failed": len(run_info.failed),
                "what": "per-episode Parquet parts, consolidation, exact evaluation of the 4 policies",
            }
        )
        seconds, run_info = _study(21, "sumo", Path(folder) / "paper")
        results.append(
            {
                "name": "study.sumo.paper_size.seconds",
                "value": seconds,
                "unit": "s",
                "episodes": 84,
                "workers": WORKERS,
                "target": 60.0,
                "failed": len(run_info.failed),
            }
        )
    # The large SUMO study against bare libsumo loops driving its very routes (same process count).
    large = study_against_bare(SUMO_LARGE_PARTICIPANTS, WORKERS, conditions=("aware", "free"))
    results.append(
        {
            "name": "study.sumo.4000_episodes.seconds",
            "value": large["value"],
            "unit": "s",
            "episodes": large["episodes"],
            "workers": WORKERS,
            "target": 900.0,
            "failed": large["failed"],
        }
    )
    results.append(large)
    return results
