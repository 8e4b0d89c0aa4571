"""Driver populations on the paper's town: exact satisfaction of free, aware, Bayes and robust
policies per true driver type, and synthesis time and memory for 1, 3 and 5 types.

Rows: drivers drawn from (i) the nominal model, (ii) the three-type example mixture
(participants/data/driver_population_three_types.json), (iii) the fitted real population when
participants/data/driver_population_real.json exists. Columns, for φ1 and φ2 at H = 20:
- free: the trust-free shortest completion;
- aware: synthesized for the nominal model (its AV filters with the nominal model);
- bayes: synthesized for the mixture's prior-weighted value (its AV filters with the type-aware
  model of the mixture);
- robust: the worst-type objective over the mixture (grid of candidate type priors).
Each entry is P(accepted within 20 junctions) (no fallback, as synthesis scores it), exact
(policies/evaluation/plain.py with the true driver of each type), per type and prior-weighted over
the row's population, certified [lower, upper] as a population synthesis reports them (each type's
rounded outward for its true driver, `TypeValue.certified`; the mixture's by `mixture_lower` and
`mixture_upper`); the lower end is printed. Belief atoms read each
vehicle's own filter (the spec's meaning), so a vehicle whose model is wrong about the driver can
count `hightrust` as reached while the driver's trust did not move. So each entry also has the
reference reading `ref`: the same episodes with the spec read on the exact posterior under the
row's population (its type-aware filter; the nominal filter for the nominal row), which is the
belief a vehicle with the right model of the drivers would hold. Beside each, E[final true trust].

Timing: `synthesize_population(objective="bayes")` on φ1 at H = 20 (time limit TIMING_TIME_LIMIT)
for populations of 1, 3 and 5 types (the example's three plus two drawn from a `[population]`
around the nominal model): wall seconds, the abstraction's build time, nodes and peak traced
memory (tracemalloc; numpy's arrays are traced), all in one run on a loaded machine: compare the
ratios, not the seconds.
Run: `.venv/bin/python -m benchmarks bench_population`.
"""

from __future__ import annotations

import time
import tracemalloc
from pathlib import Path

import numpy as np

from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.participants.driver_population import (
    EXAMPLE_POPULATION_PATH,
    DriverPopulation,
    DriverType,
    load_driver_population,
    single_type_population,
)
from trustroute.participants.population import PopulationConfig, sample_population
from trustroute.policies.belief.driver_types import lift_population, lift_spec
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.free import trust_free_policy
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.population import (
    TypeValue,
    mixture_lower,
    mixture_upper,
    synthesize_population,
)
from trustroute.policies.synthesis.result import SearchRun
from trustroute.policies.synthesis.rounding import model_rounding
from trustroute.policies.synthesis.settings import SynthesisSettings

SPECS = ("phi1", "phi2")
HORIZON = 20
TAU = 1e-3
TIME_LIMIT = 30.0          # per synthesis run
TIMING_TIME_LIMIT = 90.0
ROWS = ("nominal", "three_types", "real")   # which rows to measure (a run can be split by rows)
RUN_TIMING = True
GRID_POINTS = 3            # candidate priors of the robust objective (K = 3: the vertices)
REAL_POPULATION = EXAMPLE_POPULATION_PATH.parent / "driver_population_real.json"
SPEC_DIR = Path(__file__).resolve().parents[1] / "trustroute" / "core" / "specs"


def row_values(av_pomdp, av_spec, policy, population: DriverPopulation, spec) -> dict:
    """Exact P(accepted within H) of `policy` (its AV on av_pomdp) for each type of `population`
    and over their mixture, certified as a population synthesis certifies them, and the reference
    reading on the population's own filter."""
    reference = (build_pomdp(av_pomdp.town, lift_population(population)), lift_spec(spec, population))
    per_type, certified = {}, []
    for t in population.types:
        truth = build_pomdp(av_pomdp.town, t.model)
        value = evaluate(av_pomdp, av_spec, policy,
                         EvaluationSettings(fallback_after=None, max_junctions=HORIZON),
                         truth=truth, reference=reference)
        certified.append(TypeValue.certified(t.name, float(t.weight), (value.lower, value.upper),
                                             model_rounding(truth), value.max_junctions))
        per_type[t.name] = {"weight": t.weight, "lower": certified[-1].lower, "upper": certified[-1].upper,
                            "ref": value.reference_accepted, "final_trust": value.expected_final_trust}
    weights = population.weights
    return ({"lower": mixture_lower(weights, certified), "upper": mixture_upper(weights, certified)}
            | {key: float(weights @ [v[key] for v in per_type.values()]) for key in ("ref", "final_trust")}
            | {"per_type": per_type})


def five_types(nominal, example: DriverPopulation) -> DriverPopulation:
    rng = np.random.default_rng(20240515)
    drawn = sample_population(nominal, 2, PopulationConfig(concentration=20.0, takeover_spread=0.5), rng)
    types = [DriverType(t.name, 0.2, t.model) for t in example.types]
    types += [DriverType(f"drawn{j}", 0.2, m) for j, m in enumerate(drawn)]
    return DriverPopulation(types=tuple(types), source_path="<3 example types + 2 drawn>")


def run() -> list[dict]:
    town = load_town(None)
    nominal = load_driver_model()
    example = load_driver_population(EXAMPLE_POPULATION_PATH)
    rows = {"nominal": single_type_population(nominal), "three_types": example}
    if REAL_POPULATION.is_file():
        rows["real"] = load_driver_population(REAL_POPULATION)
    rows = {name: population for name, population in rows.items() if name in ROWS}
    results = []
    for spec_name in SPECS:
        spec = load_spec(SPEC_DIR / f"{spec_name}.toml", town)
        nominal_pomdp = build_pomdp(town, nominal)
        started = time.perf_counter()
        aware = synthesize(nominal_pomdp, spec,
                           SynthesisSettings(tau=TAU, time_limit=TIME_LIMIT, horizon=HORIZON))
        aware_seconds = time.perf_counter() - started
        robust = synthesize_population(town, example, spec, "robust",
                                       SynthesisSettings(tau=TAU, time_limit=TIME_LIMIT, horizon=HORIZON,
                                                         grid_points=GRID_POINTS))
        columns = {
            "free": (nominal_pomdp, spec, trust_free_policy(town, spec)),
            "aware": (nominal_pomdp, spec, aware.policy),
            "bayes": (robust.pomdp, robust.spec, robust.bayes_policy),
            "robust": (robust.pomdp, robust.spec, robust.result.policy),
        }
        table = {row: {column: row_values(*entry, population, spec) for column, entry in columns.items()}
                 for row, population in rows.items()}
        results.append({
            "name": f"bench_population/{spec_name}",
            "horizon": HORIZON,
            "time_limit_per_synthesis": TIME_LIMIT,
            "aware": {"lower": aware.lower, "upper": aware.upper, "seconds": aware_seconds},
            "bayes_synthesis": {"lower": robust.bayes_lower, "upper": robust.bayes_upper},
            "robust_synthesis": {"certified_worst_type": robust.lower, "upper": robust.upper,
                                 "type_upper": list(robust.type_upper), "prior": list(robust.prior),
                                 "candidates": robust.candidates, "seconds": robust.seconds},
            "table": table,
        })
        print(format_table(spec_name, table), flush=True)
    if RUN_TIMING:
        results.append(timing(town, nominal, example))
    return results


def format_table(spec_name: str, table: dict) -> str:
    lines = [f"# {spec_name}, H = {HORIZON}: P(accepted within {HORIZON}) lower end / reference reading, "
             "per type in ()"]
    for row, columns in table.items():
        cells = []
        for column, value in columns.items():
            types = ", ".join(f"{name} {v['lower']:.3f}/{v['ref']:.3f}"
                              for name, v in value["per_type"].items())
            cells.append(f"{column} {value['lower']:.4f}/{value['ref']:.4f} ({types})")
        lines.append(f"{row}: " + " | ".join(cells))
    return "\n".join(lines)


def timing(town, nominal, example: DriverPopulation) -> dict:
    spec = load_spec(SPEC_DIR / "phi1.toml", town)
    populations = {1: single_type_population(nominal), 3: example, 5: five_types(nominal, example)}
    out = {}
    for k, population in populations.items():
        tracemalloc.start()
        started = time.perf_counter()
        found = synthesize_population(town, population, spec, "bayes",
                                      SynthesisSettings(tau=TAU, time_limit=TIMING_TIME_LIMIT,
                                                        horizon=HORIZON))
        seconds = time.perf_counter() - started
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        run0 = found.result.stats.runs[0]
        search = run0 if isinstance(run0, SearchRun) else None
        out[str(k)] = {"seconds_total": seconds, "synthesis_seconds": found.result.seconds,
                       "peak_mib": peak / 2**20, "lower": found.lower, "upper": found.upper,
                       "converged": found.result.stats.converged, "nodes": run0.nodes,
                       "expanded_nodes": search and search.expanded_nodes,
                       "abstraction_seconds": search and search.abstraction_seconds,
                       "suffix_length": search and search.suffix_length,
                       "abstract_cells": search and search.abstract_cells}
    base = out["1"]["synthesis_seconds"]
    for entry in out.values():
        entry["synthesis_seconds_ratio_to_1_type"] = entry["synthesis_seconds"] / base
    return {"name": "bench_population/timing_phi1_H20", "time_limit": TIMING_TIME_LIMIT, "types": out}
