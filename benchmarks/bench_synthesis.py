"""Synthesis bounds and time: spec × belief rule × horizon, beside pomdp-py POUCT and the paper.

For φ1, φ2 and the two strict specs, under the exact Bayes filter and the authors' released update
("paper"), for horizons 6, 7, 8, 10, 12, 20 and unbounded: lower, upper, gap and seconds of
`synthesize(tau=1e-3, time_limit=60)`. At H = 20 also the exact value of "policy, then
fallback after 20" (what the study measures, with the true Bayes observation probabilities),
certified as `trustroute evaluate` reports it, and its expected final trust; per spec
pomdp-py POUCT's Monte Carlo satisfaction rate (with the fallback) and planning time per decision.
The paper's Pr_max (0.8357 / 0.7288, τ = 0.01, unbounded) is reported beside φ1 / φ2, and beside
it an emulation of the paper's finite belief approximation: the belief MDP restricted to the 210
points of the resolution-4 grid on the trust simplex (the closest regular grid to their 205 points),
every posterior snapped to the nearest grid point and labelled there. That emulation is NOT sound
(its value is neither a lower nor an upper bound); it only shows how much a coarse grid moves the
number.
Run: `.venv/bin/python -m benchmarks bench_synthesis`.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import cKDTree

from trustroute.analysis import paper_figures
from trustroute.app.synthesis import evaluate_single
from trustroute.harness.simulation.model_engine import monte_carlo
from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.policies.belief.problem import problem_of
from trustroute.policies.belief.product_mdp import build_product
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import BeliefRule, build_pomdp
from trustroute.policies.pomdp_py.pouct import pouct_policy
from trustroute.policies.routing.fallback import DEFAULT_FALLBACK_AFTER
from trustroute.policies.synthesis.belief_cells import apply_symbol, observation_symbols
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.settings import SynthesisSettings

SPECS = ("phi1", "phi2", "phi1_strict", "phi2_strict")
RULES: tuple[BeliefRule, ...] = ("bayes", "paper")
HORIZONS = (6, 7, 8, 10, 12, 20, None)
PAPER_PR_MAX = paper_figures.PR_MAX
TAU = 1e-3
TIME_LIMIT = 60.0
POUCT_EPISODES = 30
POUCT_SIMS = 100
POUCT_DEPTH = 20
GRID_RESOLUTION = 4
GRID_HORIZONS = {"phi1": (6, 20, None), "phi2": (8, 20, None)}   # shortest task route, study, unbounded


def simplex_grid(resolution: int, n: int) -> np.ndarray:
    """All beliefs with coordinates in multiples of 1/resolution."""
    points = []
    for cut in itertools.combinations(range(resolution + n - 1), n - 1):
        points.append((np.diff((-1,) + cut + (resolution + n - 1,)) - 1) / resolution)
    return np.array(points)


def grid_emulation(pomdp, spec, rule: str, resolution: int, horizon: int | None) -> float:
    """Value of the grid-snapped belief MDP (the paper's kind of approximation; unsound)."""
    tables = build_product(pomdp, spec)
    symbols = observation_symbols(pomdp, rule)
    grid = simplex_grid(resolution, pomdp.n_trust)
    tree = cKDTree(grid)
    weights = 2 ** np.arange(len(tables.belief_atom_names))

    def bits(beliefs: np.ndarray) -> np.ndarray:
        true = tables.belief_offsets[None, :] - beliefs @ tables.belief_coeffs.T < 0
        return (true * weights).sum(axis=1)

    shape = (grid.shape[0], symbols.n_symbols)
    snapped, probability, label = np.zeros(shape, int), np.zeros(shape), np.zeros(shape, int)
    for o in range(symbols.n_symbols):
        posterior, probability[:, o] = apply_symbol(grid, symbols, np.full(grid.shape[0], o))
        snapped[:, o] = tree.query(posterior)[1]
        label[:, o] = bits(grid[snapped[:, o]])
    live = ~(tables.accepting | tables.rejecting)

    def backup(value: np.ndarray) -> np.ndarray:
        out = np.zeros_like(value)
        out[:, tables.accepting, :] = 1.0
        for x in range(tables.n_x):
            best = np.zeros(value.shape[1:])
            for x2 in tables.successors[x][tables.successors[x] >= 0]:
                total = np.zeros(value.shape[1:])
                for o in symbols.by_incident[int(pomdp.road_incident[x2])]:
                    q2 = tables.next_q[:, x2, :][:, label[:, o]]
                    total += probability[None, :, o] * value[x2][q2, snapped[None, :, o]]
                best = np.maximum(best, total)
            out[x, live] = best[live]
        return out

    value = np.zeros((tables.n_x, tables.n_q, grid.shape[0]))
    value[:, tables.accepting, :] = 1.0
    for _ in range(horizon - 1 if horizon is not None else 5000):   # from 0: the least fixed point
        new = backup(value)
        if horizon is None and np.abs(new - value).max() < 1e-12:
            break
        value = new
    # First move from the exact initial belief, then on the grid.
    b0 = np.asarray(pomdp.initial_belief, dtype=float)[None, :]
    best = 0.0
    for x2 in tables.successors[tables.start][tables.successors[tables.start] >= 0]:
        total = 0.0
        for o in symbols.by_incident[int(pomdp.road_incident[x2])]:
            posterior, p = apply_symbol(b0, symbols, np.array([o]))
            g = int(tree.query(posterior[0])[1])
            q2 = tables.next_q[tables.initial_q, x2, bits(grid[g][None])[0]]
            total += float(p[0]) * value[x2, q2, g]
        best = max(best, total)
    return best


def with_fallback(pomdp, spec, policy, rule: BeliefRule) -> dict:
    """What the study measures: the policy, then the fallback after 20 junctions, with the true
    (Bayes) observation probabilities even when the AV filters by "paper"; certified as
    `trustroute evaluate` reports it."""
    study = evaluate_single(problem_of(pomdp, spec), policy,
                            EvaluationSettings(fallback_after=DEFAULT_FALLBACK_AFTER, belief_rule=rule))
    return {"with_fallback20_lower": study.lower, "with_fallback20_upper": study.upper,
            "with_fallback20_final_trust": study.expected_final_trust}


def run() -> list[dict]:
    town, driver = load_town(), load_driver_model()
    pomdp = build_pomdp(town, driver)
    results: list[dict] = []
    for name in SPECS:
        spec = load_spec(f"specs/{name}.toml", town)
        for rule in RULES:
            for horizon in HORIZONS:
                result = synthesize(pomdp, spec,
                                    SynthesisSettings(tau=TAU, time_limit=TIME_LIMIT, horizon=horizon,
                                                      belief_rule=rule))
                label = "unbounded" if horizon is None else f"H{horizon}"
                row = {"name": f"synthesis.{name}.{rule}.{label}", "value": result.lower,
                       "unit": "probability", "lower": result.lower, "upper": result.upper,
                       "gap": result.gap, "seconds": result.seconds, "converged": result.stats.converged,
                       "policy_rows": result.stats.policy_rows,
                       "paper_pr_max": PAPER_PR_MAX.get(name)}
                if horizon == DEFAULT_FALLBACK_AFTER:
                    row.update(with_fallback(pomdp, spec, result.policy, rule))
                results.append(row)
        for rule in RULES:
            for horizon in GRID_HORIZONS.get(name, ()):
                label = "unbounded" if horizon is None else f"H{horizon}"
                results.append({"name": f"synthesis.{name}.{rule}.{label}.paper_grid_emulation",
                                "value": grid_emulation(pomdp, spec, rule, GRID_RESOLUTION, horizon),
                                "unit": "probability (unsound approximation)",
                                "grid_points": int(simplex_grid(GRID_RESOLUTION, pomdp.n_trust).shape[0]),
                                "paper_pr_max": PAPER_PR_MAX.get(name)})
        rng = np.random.default_rng(7)
        planner = pouct_policy(pomdp, spec, rng, num_sims=POUCT_SIMS, max_depth=POUCT_DEPTH)
        pouct = monte_carlo(pomdp, spec, planner, POUCT_EPISODES, rng)
        results.append({"name": f"synthesis.{name}.pouct", "value": pouct.satisfaction,
                        "unit": "probability", "standard_error": pouct.standard_error,
                        "episodes": pouct.episodes, "num_sims": POUCT_SIMS, "max_depth": POUCT_DEPTH,
                        "fallback_after": 20, "seconds_per_decision": pouct.seconds_per_decision,
                        "seconds": pouct.seconds})
    return results
