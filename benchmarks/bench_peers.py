"""One peer table: ours, Storm and PAYNT on the same problems, in one run (docs/peers.md).

Problems: the paper's town with φ1 and φ2 (H = 20), φ1 with the trust-state atom (H = 20 and
unbounded), the 5 × 5 and 5 × 10 grids of benchmarks/bench_storm.py (H = 20) and the 200-junction
grid of benchmarks/bench_synthesis_scaling.py (5 waypoint sets, H = 40). Ours is `trustroute
synth` (policies/synthesize_spec.py: L the returned policy's exact value, U the search's); Storm
gives [lower, upper] (belief unfolding, discretisation); PAYNT the value of its best finite-state
controller (a lower bound). Each side runs in its own spawned process, so its peak resident
memory is its own, and carries the 1-minute load average at its start. Where a peer cannot express
a problem (belief atoms), the row says so. The table goes to stderr, one JSON line per problem to
stdout.
"""

from __future__ import annotations

import os
import sys
import time

from benchmarks.timing import in_spawned_process, peak_rss_mb
from trustroute.core.wording import interval, lower_text
from trustroute.policies.synthesis.settings import SynthesisSettings

OUR_TAU = 1e-3
OUR_TIME_LIMIT = 60
STORM_TIME_LIMIT = 20          # seconds of Storm's belief unfolding
STORM_RESOLUTION = 2
PAYNT_TIME_LIMIT = 20          # seconds of PAYNT's controller search

PROBLEMS = (("paper_phi1_h20", "paper", "phi1", 20), ("paper_phi2_h20", "paper", "phi2", 20),
            ("paper_phi1_trust_h20", "paper", "phi1_trust", 20),
            ("paper_phi1_trust_unbounded", "paper", "phi1_trust", None),
            ("grid5x5_phi1_trust_h20", "grid25", None, 20), ("grid5x10_phi1_trust_h20", "grid50", None, 20),
            ("grid200_5waypoints_h40", "grid200", None, 40))


def problem(town_kind: str, paper_spec: str | None):
    """(pomdp, spec) of one row."""
    from benchmarks.bench_storm import GRIDS, grid_spec_text, grid_town
    from benchmarks.bench_synthesis_scaling import grid_or_paper_problem
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.policies.logic.spec import spec_from_text
    from trustroute.policies.model.trust_pomdp import build_pomdp

    if town_kind == "paper":
        return grid_or_paper_problem(0, 0, paper_spec)
    if town_kind == "grid200":
        return grid_or_paper_problem(200, 5, None)
    rows, columns = GRIDS[town_kind]
    town = grid_town(rows, columns)
    spec = spec_from_text(grid_spec_text(rows, columns), f"<{town_kind} spec>", town)
    return build_pomdp(town, load_driver_model()), spec


def _ours(queue, town_kind: str, paper_spec: str | None, horizon: int | None) -> None:
    from trustroute.policies.synthesize_spec import synthesize_spec

    pomdp, spec = problem(town_kind, paper_spec)
    started = time.perf_counter()
    result = synthesize_spec(pomdp, spec,
                             SynthesisSettings(tau=OUR_TAU, time_limit=OUR_TIME_LIMIT, horizon=horizon))
    queue.put({"lower": result.lower, "upper": result.upper, "seconds": time.perf_counter() - started,
               "peak_rss_mb": peak_rss_mb()})


def _storm(queue, town_kind: str, paper_spec: str | None, horizon: int | None) -> None:
    from trustroute.core.errors import InputError
    from trustroute.policies.peer.product_pomdp import explicit_product
    from trustroute.policies.peer.storm import run_storm

    pomdp, spec = problem(town_kind, paper_spec)
    started = time.perf_counter()
    try:
        product = explicit_product(pomdp, spec, horizon)
    except InputError as exc:
        queue.put({"cannot_express": exc.problem})
        return
    result = run_storm(product, time_limit=STORM_TIME_LIMIT, resolution=STORM_RESOLUTION)
    queue.put({"lower": result.lower, "upper": result.upper, "product_states": product.n_states,
               "seconds": time.perf_counter() - started, "peak_rss_mb": peak_rss_mb()})


def _paynt(queue, town_kind: str, paper_spec: str | None, horizon: int | None) -> None:
    from trustroute.core.errors import InputError
    from trustroute.policies.peer.paynt import run_paynt
    from trustroute.policies.peer.product_pomdp import explicit_product

    pomdp, spec = problem(town_kind, paper_spec)
    started = time.perf_counter()
    try:
        result = run_paynt(explicit_product(pomdp, spec, horizon), time_limit=PAYNT_TIME_LIMIT)
    except InputError as exc:
        queue.put({"cannot_express": exc.problem})
        return
    queue.put({"value": result.value, "memory_nodes": result.memory_nodes,
               "seconds": time.perf_counter() - started, "peak_rss_mb": peak_rss_mb()})


def _ratio(ours: dict, peer: dict, key: str) -> float | None:
    return ours[key] / peer[key] if key in peer and peer[key] else None


def _cell(side: dict) -> str:
    if "skipped" in side:
        return side["skipped"]
    if "cannot_express" in side:
        return "cannot express: belief atoms"
    if "value" in side:
        value = "none found" if side["value"] is None else f"{lower_text(side['value'], 5)} (lower)"
        return (f"{value} k<={side['memory_nodes']} {side['seconds']:.0f} s {side['peak_rss_mb']:.0f} MB"
                f" load {side['load_average_1min']:.1f}")
    return (f"{interval(side['lower'], side['upper'], 5)} {side['seconds']:.1f} s "
            f"{side['peak_rss_mb']:.0f} MB load {side['load_average_1min']:.1f}")


def _side(target, args: tuple, available: bool, absent: str) -> dict:
    """One side of a row in its own spawned process, with the 1-minute load average at its start
    (the machine is shared: above 2 on its 2 cores, wall time includes the wait for a core)."""
    if not available:
        return {"skipped": absent}
    load = os.getloadavg()[0]
    return {**in_spawned_process(target, *args), "load_average_1min": load}


def run(problems: tuple[tuple[str, str, str | None, int | None], ...] = PROBLEMS) -> list[dict]:
    from trustroute.policies.peer.paynt import paynt_available
    from trustroute.policies.peer.storm import storm_available

    rows = []
    for name, town_kind, paper_spec, horizon in problems:
        args = (town_kind, paper_spec, horizon)
        ours = _side(_ours, args, True, "")
        storm = _side(_storm, args, storm_available(), "stormpy absent")
        paynt = _side(_paynt, args, paynt_available(), "paynt absent")
        rows.append({"name": f"peers_{name}", "horizon": horizon, "ours": ours, "storm": storm,
                     "paynt": paynt,
                     "time_ratio_ours_over_storm": _ratio(ours, storm, "seconds"),
                     "memory_ratio_ours_over_storm": _ratio(ours, storm, "peak_rss_mb"),
                     "time_ratio_ours_over_paynt": _ratio(ours, paynt, "seconds"),
                     "memory_ratio_ours_over_paynt": _ratio(ours, paynt, "peak_rss_mb")})
        print(f"{name:28s} ours {_cell(ours)} | storm {_cell(storm)} | paynt {_cell(paynt)}",
              file=sys.stderr, flush=True)
    return rows
