"""Storm beside our joint-belief search on the paper's town: φ1 with the trust atom θ >= 6 at v3.

Bounded objective with a step counter (H = 20 junctions, as in docs/trust_states.md). Each side
runs in its own spawned process so that its peak resident memory (ru_maxrss, which includes
Storm's C++ heap) is its own. Reports both bounds, both times, the memory, and ratios ours/Storm
measured in this run. Skipped (one line saying so) when the optional `[peer]` extra is absent.
"""

from __future__ import annotations

import multiprocessing
import resource
import time

HORIZON = 20
STORM_TIME_LIMIT = 60          # seconds of Storm's belief unfolding (its lower bound)
STORM_RESOLUTION = 2           # Storm's discretisation (its upper bound)
OUR_MAX_NODES = 2_000          # our belief nodes per level


def _problem():
    from trustroute.networks.town import load_town
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.policies.logic.spec import load_spec
    from trustroute.policies.model.trust_pomdp import build_pomdp

    town = load_town()
    return build_pomdp(town, load_driver_model()), load_spec("specs/phi1_trust.toml", town)


def _storm(queue) -> None:
    from trustroute.policies.peer.product_pomdp import explicit_product
    from trustroute.policies.peer.storm import run_storm

    pomdp, spec = _problem()
    started = time.perf_counter()
    product = explicit_product(pomdp, spec, HORIZON)
    export_seconds = time.perf_counter() - started
    result = run_storm(product, time_limit=STORM_TIME_LIMIT, resolution=STORM_RESOLUTION)
    queue.put({"lower": result.lower, "upper": result.upper, "product_states": product.n_states,
               "seconds": export_seconds + result.build_seconds + result.lower_seconds
               + result.upper_seconds, "lower_seconds": result.lower_seconds,
               "upper_seconds": result.upper_seconds, "lower_beliefs": result.lower_beliefs,
               "lower_complete": result.lower_complete,
               "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024})


def _ours(queue) -> None:
    from trustroute.policies.joint_search import joint_bounds

    pomdp, spec = _problem()
    started = time.perf_counter()
    result = joint_bounds(pomdp, spec, depth=HORIZON, horizon=HORIZON, max_nodes=OUR_MAX_NODES)
    queue.put({"lower": result.lower, "upper": result.upper, "nodes": result.nodes,
               "cut_nodes": result.cut_nodes, "seconds": time.perf_counter() - started,
               "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024})


def _in_process(target) -> dict:
    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    process = context.Process(target=target, args=(queue,))
    process.start()
    result = queue.get()
    process.join()
    return result


def run() -> list[dict]:
    from trustroute.policies.peer.storm import storm_available

    name = "storm_vs_ours_phi1_trust_h20"
    if not storm_available():
        return [{"name": name, "skipped": "stormpy absent: pip install -e '.[peer]'"}]
    storm = _in_process(_storm)
    ours = _in_process(_ours)
    return [{
        "name": name, "horizon": HORIZON, "storm": storm, "ours": ours,
        "storm_gap": storm["upper"] - storm["lower"], "ours_gap": ours["upper"] - ours["lower"],
        "time_ratio_ours_over_storm": ours["seconds"] / storm["seconds"],
        "memory_ratio_ours_over_storm": ours["peak_rss_mb"] / storm["peak_rss_mb"],
        "overlap": max(storm["lower"], ours["lower"]) <= min(storm["upper"], ours["upper"]) + 1e-6,
    }]
