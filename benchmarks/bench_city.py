"""Synthesis at city scale: the 5-waypoint specs of the packaged cities at H = 40 and unbounded,
`city5` on the town `city` (the RESCO Ingolstadt scenario) and `csomor5` on the town `csomor`
(RouteRL's OpenStreetMap net of Csömör, 481 choice junctions; docs/cities.md).

Per city, first the trust-free baseline of the same run: the shortest route completing the task
and its exact value, certified, as `trustroute baseline` gives them (the lower end is the row's
value; the seconds are the whole baseline's). Then each synthesis `synthesize(tau=1e-3,
time_limit=60)` in a fresh subprocess (its own peak RSS, no warm caches): seconds, peak RSS (MB),
L, U, whether the target is met (gap <= 1e-3 within 60 s under 1 GB), and whether L stays at or
above the trust-free value minus the gap. The machine is shared: every row carries the 1-minute
load average measured beside it, and synthesis seconds are also given per second of the
baseline's evaluation. `city` needs the optional extra `cities` (pip install
'trustroute[cities]'); without it one row says so. `csomor` ships with the package.
Run: `.venv/bin/python -m benchmarks bench_city`.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
import time

from benchmarks.bench_synthesis_scaling import MEMORY_TARGET_MB, TAU, TIME_LIMIT, run_json_subprocess
from trustroute.policies.synthesis.settings import SynthesisSettings

# (row name prefix, spec, town)
CITIES = (("city", "city5", "city"), ("csomor", "csomor5", "csomor"))
HORIZONS = (40, None)


def _problem(spec_name: str, town_name: str):
    from trustroute.networks.town import load_town
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.policies.logic.spec import load_spec
    from trustroute.policies.model.trust_pomdp import build_pomdp

    town = load_town(town_name)
    driver = load_driver_model()
    return town, build_pomdp(town, driver), load_spec(spec_name, town, driver.n_trust)


def _child(spec_name: str, town_name: str, horizon: int | None) -> dict:
    """Runs in the subprocess: one synthesis, its numbers and the process's peak RSS."""
    from benchmarks.timing import peak_rss_mb
    from trustroute.policies.synthesis.belief_synthesis import synthesize

    _, pomdp, spec = _problem(spec_name, town_name)
    result = synthesize(pomdp, spec, SynthesisSettings(tau=TAU, time_limit=TIME_LIMIT, horizon=horizon))
    rss_mb = peak_rss_mb()
    return {"lower": result.lower, "upper": result.upper, "seconds": result.seconds, "rss_mb": rss_mb}


def baseline_row(prefix: str, spec_name: str, town_name: str) -> dict:
    """The trust-free baseline as `trustroute baseline` gives it: its route and certified value."""
    from trustroute.app.synthesis import baseline
    from trustroute.networks.road_lookup import choice_junctions
    from trustroute.policies.belief.problem import problem_of

    town, pomdp, spec = _problem(spec_name, town_name)
    load = os.getloadavg()[0]
    start = time.perf_counter()
    found = baseline(problem_of(pomdp, spec))
    seconds = time.perf_counter() - start
    return {"name": f"{prefix}.trust_free", "value": found.value.lower, "unit": "probability",
            "upper": found.value.upper, "seconds": seconds, "junctions": len(town.junctions),
            "roads": len(town.states), "choice_junctions": len(choice_junctions(town)),
            "route_junctions": len(found.route) - 1, "route_m": found.length_m, "load_average_1min": load}


def _synthesis_row(prefix: str, spec_name: str, town_name: str, horizon: int | None, free: float,
                   baseline_seconds: float) -> dict:
    """One synthesis in a fresh subprocess, against the trust-free value `free`."""
    load = os.getloadavg()[0]
    out = run_json_subprocess("benchmarks.bench_city", [spec_name, town_name, horizon], TIME_LIMIT * 5)
    label = "unbounded" if horizon is None else str(horizon)
    row = {"name": f"{prefix}.synthesis.{label}", "value": out.get("seconds"), "unit": "s",
           "horizon": horizon, "load_average_1min": [load, os.getloadavg()[0]], **out,
           "target": f"gap <= {TAU} within {TIME_LIMIT:.0f} s under {MEMORY_TARGET_MB:.0f} MB"}
    if "error" not in out:
        gap = out["upper"] - out["lower"]
        row.update(gap=gap, target_met=bool(gap <= TAU and out["seconds"] <= TIME_LIMIT * 1.02
                                            and out["rss_mb"] < MEMORY_TARGET_MB),
                   trust_free=free, lower_above_trust_free=bool(out["lower"] >= free - gap),
                   seconds_vs_baseline=out["seconds"] / max(baseline_seconds, 1e-9))
    return row


def _city_rows(prefix: str, spec_name: str, town_name: str, table: list[str]) -> list[dict]:
    baseline = baseline_row(prefix, spec_name, town_name)
    results = [baseline]
    table += [f"{prefix} ({baseline['junctions']} junctions, {baseline['choice_junctions']} with a choice): "
              f"trust-free P = {baseline['value']:.6f} ({baseline['seconds']:.3f} s)",
              f"{'H':>9} {'seconds':>8} {'RSS MB':>7} {'L':>9} {'U':>9} target"]
    for horizon in HORIZONS:
        row = _synthesis_row(prefix, spec_name, town_name, horizon, baseline["value"], baseline["seconds"])
        label = "unbounded" if horizon is None else str(horizon)
        if "error" in row:
            table.append(f"{label:>9} error: {row['error'][:60]}")
        else:
            table.append(f"{label:>9} {row['seconds']:8.2f} {row['rss_mb']:7.0f} {row['lower']:9.6f} "
                         f"{row['upper']:9.6f} {'yes' if row['target_met'] else 'no'}")
        results.append(row)
    return results


def run() -> list[dict]:
    results: list[dict] = []
    table: list[str] = []
    for prefix, spec_name, town_name in CITIES:
        if town_name == "city" and importlib.util.find_spec("sumo_rl") is None:
            results.append({"name": "city",
                            "error": "needs the optional extra: pip install 'trustroute[cities]'"})
            continue
        results += _city_rows(prefix, spec_name, town_name, table)
    print("\n".join(table), file=sys.stderr, flush=True)
    return results


if __name__ == "__main__":
    print(json.dumps(_child(*json.loads(sys.argv[1]))))
