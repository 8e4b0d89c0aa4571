"""Synthesis bounds and time: spec × belief rule × horizon, beside pomdp-py POUCT and the paper.

For φ1, φ2 and the two strict specs, under the exact Bayes filter and the authors' released update
("paper"), for horizons 6, 7, 8, 10, 12, 20 and unbounded: lower, upper, gap and seconds of
`synthesize(tau=1e-3, time_limit=60)`. For the Bayes rule at H = 20 also the exact value of
"policy, then fallback after 20" (what the study measures) and its expected final trust; per spec
pomdp-py POUCT's Monte Carlo satisfaction rate (with the fallback) and planning time per decision.
The paper's Pr_max (0.8357 / 0.7288, τ = 0.01, unbounded) is reported beside φ1 / φ2.
Run: `.venv/bin/python -m benchmarks bench_synthesis`.
"""

from __future__ import annotations

import numpy as np

from networks.town import load_town
from participants.driver_model import load_driver_model
from policies.evaluate import evaluate
from policies.pouct_baseline import monte_carlo, pouct_policy
from policies.spec import load_spec
from policies.synthesis import synthesize
from policies.trust_pomdp import build_pomdp

SPECS = ("phi1", "phi2", "phi1_strict", "phi2_strict")
RULES = ("bayes", "paper")
HORIZONS = (6, 7, 8, 10, 12, 20, None)
PAPER_PR_MAX = {"phi1": 0.8357, "phi2": 0.7288}
TAU = 1e-3
TIME_LIMIT = 60.0
POUCT_EPISODES = 30
POUCT_SIMS = 100
POUCT_DEPTH = 20


def run() -> list[dict]:
    town, driver = load_town(), load_driver_model()
    pomdp = build_pomdp(town, driver)
    results: list[dict] = []
    for name in SPECS:
        spec = load_spec(f"specs/{name}.toml", town)
        for rule in RULES:
            for horizon in HORIZONS:
                result = synthesize(pomdp, spec, tau=TAU, time_limit=TIME_LIMIT, horizon=horizon,
                                    belief_rule=rule)
                label = "unbounded" if horizon is None else f"H{horizon}"
                row = {"name": f"synthesis.{name}.{rule}.{label}", "value": result.lower,
                       "unit": "probability", "lower": result.lower, "upper": result.upper,
                       "gap": result.gap, "seconds": result.seconds, "converged": result.stats["converged"],
                       "policy_rows": result.stats["policy_rows"],
                       "paper_pr_max": PAPER_PR_MAX.get(name)}
                if horizon == 20 and rule == "bayes":
                    study = evaluate(pomdp, spec, result.policy, fallback_after=20)
                    row.update({"with_fallback20_lower": study.lower, "with_fallback20_upper": study.upper,
                                "with_fallback20_final_trust": study.expected_final_trust})
                results.append(row)
        rng = np.random.default_rng(7)
        planner = pouct_policy(pomdp, spec, rng, num_sims=POUCT_SIMS, max_depth=POUCT_DEPTH)
        pouct = monte_carlo(pomdp, spec, planner, POUCT_EPISODES, rng)
        results.append({"name": f"synthesis.{name}.pouct", "value": pouct.satisfaction,
                        "unit": "probability", "standard_error": pouct.standard_error,
                        "episodes": pouct.episodes, "num_sims": POUCT_SIMS, "max_depth": POUCT_DEPTH,
                        "fallback_after": 20, "seconds_per_decision": pouct.seconds_per_decision,
                        "seconds": pouct.seconds})
    return results
