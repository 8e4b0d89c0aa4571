"""How closely the synthesis of specs with trust-state atoms keeps to its time limit.

φ1 with the trust atom θ >= 6 on the paper's town and on the 5 × 5 grid of bench_storm, H = 20,
τ so small that the rounds never stop by convergence: each run ends by its time limit, with limits
shorter and longer than one round. Reports the wall time and its ratio to the limit (the target:
at most 1.02) beside the bounds returned and the 1-minute load average at the start (the machine is
shared: above 2 on its 2 cores, wall time includes the wait for a core).
"""

from __future__ import annotations

import os
import time

from benchmarks.bench_storm import HORIZON, _problem
from trustroute.policies.synthesis.settings import SynthesisSettings

RUNS = (("paper", 0.5), ("paper", 2.0), ("paper", 4.0), ("grid25", 4.0))
TAU = 1e-12
TARGET_RATIO = 1.02     # wall time at most 2 % over the limit


def time_limit_row(name: str, limit: float, seconds: float, **extra) -> dict:
    """One benchmark row: wall seconds of a run with `limit`, their ratio and whether it is within
    TARGET_RATIO."""
    return {"name": name, "time_limit": limit, "seconds": seconds, "ratio_to_limit": seconds / limit,
            "within_target": seconds <= TARGET_RATIO * limit, **extra}


def run(runs: tuple[tuple[str, float], ...] = RUNS) -> list[dict]:
    from trustroute.policies.synthesize_spec import synthesize_spec

    results = []
    for town_kind, limit in runs:
        pomdp, spec = _problem(town_kind)
        load = os.getloadavg()[0]
        started = time.perf_counter()
        result = synthesize_spec(pomdp, spec, SynthesisSettings(tau=TAU, time_limit=limit, horizon=HORIZON))
        seconds = time.perf_counter() - started
        results.append(time_limit_row(f"joint_time_limit_{town_kind}_{limit:g}s", limit, seconds,
                                      rounds=len(result.stats.runs), lower=result.lower,
                                      upper=result.upper, load_average_1min=load))
    return results
