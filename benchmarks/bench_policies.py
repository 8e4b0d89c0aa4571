"""Policy values side by side: trust-free baseline (exact), pomdp-py POUCT (Monte Carlo), synthesis.

For φ1 and φ2 on the defaults: the exact satisfaction probability of the trust-free baseline and
the time `evaluate` takes against a Monte Carlo estimate of the same number (baseline for the
ratio); POUCT's Monte Carlo satisfaction rate and planning time per decision (with the study's
20-junction fallback); `evaluate` throughput on a large policy tree; and the synthesized
(unbounded) bounds with the exact value of the aware policy with the fallback.
The paper's Pr_max (0.8357 / 0.7288) and trust-free rate (0.775) are reported as references.
Runtime is kept to a few minutes on a shared 2-core machine.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.timing import best_seconds
from networks.town import load_town
from participants.driver_model import load_driver_model
from policies.baseline import trust_free_policy
from policies.evaluate import evaluate
from policies.pouct_baseline import monte_carlo, pouct_policy
from policies.spec import load_spec
from policies.synthesis import synthesize
from policies.trust_pomdp import build_pomdp

SPECS = ("phi1", "phi2")
PAPER_PR_MAX = {"phi1": 0.8357, "phi2": 0.7288}
PAPER_TRUST_FREE_RATE = 0.775
POUCT_EPISODES = 40
POUCT_SIMS = 100
POUCT_DEPTH = 20
MC_EPISODES = 2000
SYNTHESIS_TIME_LIMIT = 60.0


class _FixedRandomPolicy:
    """Random junction per road (seeded): loops, so the fallback at 20 gives a deep tree."""

    name = "random"

    def __init__(self, town, rng: np.random.Generator) -> None:
        self.table = {road: town.actions(road)[int(rng.integers(len(town.actions(road))))]
                      for road in town.states}

    def next_junction(self, context) -> str:
        return self.table[context.road]


def run() -> list[dict]:
    town, driver = load_town(), load_driver_model()
    pomdp = build_pomdp(town, driver)
    results: list[dict] = []
    for name in SPECS:
        spec = load_spec(f"specs/{name}.toml", town)
        free = trust_free_policy(town, spec)
        exact = evaluate(pomdp, spec, free)
        exact_seconds = best_seconds(lambda spec=spec, free=free: evaluate(pomdp, spec, free), repeats=3)
        mc = monte_carlo(pomdp, spec, free, MC_EPISODES, np.random.default_rng(1))
        results.append({"name": f"policies.free.{name}.satisfaction", "value": exact.lower,
                        "unit": "probability", "upper": exact.upper,
                        "expected_final_trust": exact.expected_final_trust,
                        "paper_trust_free_rate": PAPER_TRUST_FREE_RATE,
                        "monte_carlo": mc.satisfaction, "monte_carlo_se": mc.standard_error})
        results.append({"name": f"policies.free.{name}.evaluate_seconds", "value": exact_seconds,
                        "unit": "s", "baseline": mc.seconds, "ratio": mc.seconds / exact_seconds,
                        "baseline_what": f"Monte Carlo, {MC_EPISODES} episodes (SE {mc.standard_error:.4f})"})

        rng = np.random.default_rng(7)
        planner = pouct_policy(pomdp, spec, rng, num_sims=POUCT_SIMS, max_depth=POUCT_DEPTH)
        pouct = monte_carlo(pomdp, spec, planner, POUCT_EPISODES, rng)
        results.append({"name": f"policies.pouct.{name}.satisfaction", "value": pouct.satisfaction,
                        "unit": "probability", "standard_error": pouct.standard_error,
                        "episodes": pouct.episodes, "num_sims": POUCT_SIMS, "max_depth": POUCT_DEPTH,
                        "fallback_after": 20, "mean_final_trust": pouct.mean_final_trust,
                        "paper_pr_max": PAPER_PR_MAX[name], "free_exact": exact.lower})
        results.append({"name": f"policies.pouct.{name}.seconds_per_decision",
                        "value": float(np.mean(planner.planning_seconds)), "unit": "s",
                        "decisions": len(planner.planning_seconds)})

        started = time.perf_counter()
        result = synthesize(pomdp, spec, tau=1e-3, time_limit=SYNTHESIS_TIME_LIMIT, horizon=None,
                            belief_rule="bayes")
        seconds = time.perf_counter() - started
        aware = evaluate(pomdp, spec, result.policy)
        results.append({"name": f"policies.aware.{name}.bounds", "value": result.lower,
                        "unit": "probability", "upper": result.upper, "gap": result.gap,
                        "seconds": seconds, "paper_pr_max": PAPER_PR_MAX[name],
                        "with_fallback20": aware.lower, "with_fallback20_upper": aware.upper,
                        "with_fallback20_final_trust": aware.expected_final_trust,
                        "pouct_monte_carlo": pouct.satisfaction})

    spec = load_spec("specs/phi1.toml", town)
    deep = _FixedRandomPolicy(town, np.random.default_rng(2))
    tree = evaluate(pomdp, spec, deep, fallback_after=28)
    results.append({"name": "policies.evaluate.deep_tree_nodes_per_second",
                    "value": tree.nodes / tree.seconds, "unit": "nodes/s", "nodes": tree.nodes,
                    "max_frontier": tree.max_frontier, "seconds": tree.seconds, "gap": tree.gap})
    return results
