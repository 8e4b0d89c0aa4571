"""How closely the plain synthesis (`synthesize`, policies/synthesis/belief_synthesis.py) keeps to its time
limit.

τ so small that no run stops by convergence, so each ends by its limit (or by the node budget, or
by closing exactly): the paper's town with φ1 and φ2 at H = 20 and unbounded, grid towns of 50 and
200 junctions with 5 waypoint sets (bench_synthesis_scaling's towns and spec) at H = 40 and
unbounded, limits 2 and 10 s for all and 60 s for the 200-junction grid. Each run is one fresh
subprocess (no warm caches; the call is timed inside it, from before `synthesize` to after it
returns). Reports wall and CPU seconds, the ratio of wall time to the limit (the target: at most
1.02), L, U and the 1-minute load average. The table is printed to stderr.
Run: `.venv/bin/python -m benchmarks bench_synthesis_time_limit`.
"""

from __future__ import annotations

import os
import sys
import time

from benchmarks.bench_joint_time_limit import TAU, time_limit_row
from benchmarks.bench_synthesis_scaling import grid_or_paper_problem, run_json_subprocess
from trustroute.policies.synthesis.settings import SynthesisSettings

WAYPOINTS = 5
# (label, junctions, paper spec, horizon): the paper's town at H = 20, the grids at H = 40
PROBLEMS = (("paper phi1", 0, "phi1", 20), ("paper phi2", 0, "phi2", 20),
            ("grid 50", 50, None, 40), ("grid 200", 200, None, 40))
LIMITS = (2.0, 10.0)
LONG_LIMIT = 60.0
LONG_PROBLEMS = ("grid 200",)     # the largest fixed costs; the whole bench takes about 4 minutes


def _child(junctions: int, paper_spec: str | None, horizon: int | None, limit: float) -> dict:
    """Runs in the subprocess: the problem is built before the clock starts."""
    from trustroute.policies.synthesis.belief_synthesis import synthesize

    pomdp, spec = grid_or_paper_problem(junctions, WAYPOINTS, paper_spec)
    wall, cpu = time.perf_counter(), time.process_time()
    result = synthesize(pomdp, spec, SynthesisSettings(tau=TAU, time_limit=limit, horizon=horizon))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return {"seconds": wall, "cpu_seconds": cpu, "lower": result.lower, "upper": result.upper,
            "runs": len(result.stats.runs), "nodes": result.stats.runs[-1].nodes}


def _configurations() -> list[tuple[str, int, str | None, int | None, float]]:
    runs = []
    for label, junctions, paper_spec, horizon in PROBLEMS:
        for h in (horizon, None):
            limits = LIMITS + ((LONG_LIMIT,) if label in LONG_PROBLEMS else ())
            runs += [(label, junctions, paper_spec, h, limit) for limit in limits]
    return runs


def run() -> list[dict]:
    results = []
    table = [f"{'town':>10} {'H':>9} {'limit':>6} {'wall s':>8} {'CPU s':>8} {'wall/limit':>10} "
             f"{'L':>8} {'U':>8} {'load':>5} within 2 %"]
    for label, junctions, paper_spec, horizon, limit in _configurations():
        load = os.getloadavg()[0]
        out = run_json_subprocess("benchmarks.bench_synthesis_time_limit",
                                  [junctions, paper_spec, horizon, limit], limit * 5 + 120)
        h = "unbounded" if horizon is None else str(horizon)
        name = f"synthesis_time_limit.{label.replace(' ', '')}.{h}.{limit:g}s"
        if "error" in out:
            results.append({"name": name, "time_limit": limit, **out})
            table.append(f"{label:>10} {h:>9} {limit:6g} error: {out['error'][:60]}")
        else:
            row = time_limit_row(name, limit, out.pop("seconds"), horizon=horizon,
                                 load_average_1min=load, **out)
            results.append(row)
            table.append(f"{label:>10} {h:>9} {limit:6g} {row['seconds']:8.2f} {row['cpu_seconds']:8.2f} "
                         f"{row['ratio_to_limit']:10.3f} {row['lower']:8.4f} {row['upper']:8.4f} "
                         f"{load:5.2f} {'yes' if row['within_target'] else 'no'}")
        print(table[-1], file=sys.stderr, flush=True)
    print("\n".join(table), file=sys.stderr, flush=True)
    return results


if __name__ == "__main__":
    import json

    print(json.dumps(_child(*json.loads(sys.argv[1]))))
