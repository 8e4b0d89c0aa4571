"""Exact policy evaluation: the trust-free baseline's value and `evaluate`'s speed.

For φ1 and φ2 on the defaults: the exact satisfaction probability of the trust-free baseline,
certified as `trustroute evaluate` reports it (rounded outward, policies/synthesis/rounding.py), and
the time that takes against a Monte Carlo estimate of the same number (baseline for the ratio); the
unfolding's throughput on a large policy tree. The paper's trust-free rate (0.775) is
reported as a reference. Synthesized bounds and pomdp-py POUCT are in bench_synthesis.
"""

from __future__ import annotations

import numpy as np

from benchmarks.timing import best_seconds
from trustroute.analysis import paper_figures
from trustroute.app.synthesis import certified, evaluate_single
from trustroute.harness.simulation.model_engine import monte_carlo
from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.policies.belief.problem import problem_of
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import DEFAULT_EVALUATION, EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.free import trust_free_policy
from trustroute.policies.routing.protocol import RoutingPolicy

SPECS = ("phi1", "phi2")
PAPER_TRUST_FREE_RATE = paper_figures.SATISFACTION_RATE["free"]
MC_EPISODES = 2000


class _FixedRandomPolicy(RoutingPolicy):
    """Random junction per road (seeded): loops, so the fallback at 20 gives a deep tree."""

    name = "random"

    def __init__(self, town, rng: np.random.Generator) -> None:
        self.table = {road: town.actions(road)[int(rng.integers(len(town.actions(road))))]
                      for road in town.states}

    def next_junction(self, context) -> str:
        return self.table[context.road]


def trust_free_rows(pomdp, name: str, episodes: int = MC_EPISODES) -> list[dict]:
    """The trust-free policy's certified value for the spec `name` (`trustroute evaluate`'s), and
    the seconds that takes against a Monte Carlo estimate of `episodes` episodes."""
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    free = trust_free_policy(pomdp.town, spec)
    problem = problem_of(pomdp, spec)
    exact = evaluate_single(problem, free, DEFAULT_EVALUATION)
    exact_seconds = best_seconds(lambda: evaluate_single(problem, free, DEFAULT_EVALUATION), repeats=3)
    mc = monte_carlo(pomdp, spec, free, episodes, np.random.default_rng(1))
    return [{"name": f"policies.free.{name}.satisfaction", "value": exact.lower,
             "unit": "probability", "upper": exact.upper,
             "expected_final_trust": exact.expected_final_trust,
             "paper_trust_free_rate": PAPER_TRUST_FREE_RATE,
             "monte_carlo": mc.satisfaction, "monte_carlo_se": mc.standard_error},
            {"name": f"policies.free.{name}.evaluate_seconds", "value": exact_seconds,
             "unit": "s", "baseline": mc.seconds, "ratio": mc.seconds / exact_seconds,
             "baseline_what": f"Monte Carlo, {episodes} episodes (SE {mc.standard_error:.4f})"}]


def run() -> list[dict]:
    town, driver = load_town(), load_driver_model()
    pomdp = build_pomdp(town, driver)
    results: list[dict] = []
    for name in SPECS:
        results += trust_free_rows(pomdp, name)

    spec = load_spec("specs/phi1.toml", town)
    deep = _FixedRandomPolicy(town, np.random.default_rng(2))
    tree = evaluate(pomdp, spec, deep, EvaluationSettings(fallback_after=28))
    results.append({"name": "trustroute.policies.evaluation.plain.deep_tree_nodes_per_second",
                    "value": tree.nodes / tree.seconds, "unit": "nodes/s", "nodes": tree.nodes,
                    "max_frontier": tree.max_frontier, "seconds": tree.seconds,
                    "gap": certified(problem_of(pomdp, spec), tree).gap})
    return results
