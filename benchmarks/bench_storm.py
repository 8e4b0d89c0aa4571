"""Storm beside our joint-belief search: φ1 with the trust atom θ >= 6 at v3 on the paper's town,
then the same task shape on grid towns of 25 and 50 junctions (incidents drawn with a fixed seed).

Bounded objective with a step counter (H = 20 junctions, as in docs/trust_states.md). Ours is the
synthesis `trustroute synth` runs (policies/trust_state_synthesis/synthesis.py): its lower
bound is the exact value of the policy it returns, its upper bound the search's. Each side
runs in its own spawned process so that its peak resident memory (benchmarks/timing.py
peak_rss_mb, which includes Storm's C++ heap) is its own. Reports both bounds, both times, the
memory, and ratios ours/Storm measured in this run. Skipped (one line saying so) when the
optional `[peer]` extra is absent.
"""

from __future__ import annotations

import time

from benchmarks.timing import in_spawned_process, peak_rss_mb
from trustroute.policies.synthesis.settings import SynthesisSettings

HORIZON = 20
STORM_TIME_LIMIT = 60          # seconds of Storm's belief unfolding (its lower bound)
STORM_RESOLUTION = 2           # Storm's discretisation (its upper bound)
OUR_TIME_LIMIT = 60            # seconds of our synthesis (trustroute synth --time-limit)
OUR_TAU = 1e-3


GRID_SEED = 2024


def grid_town(rows: int, columns: int):
    """A rows × columns grid, 200 m apart; each directed road's incident drawn with GRID_SEED."""
    import numpy as np

    from trustroute.networks.town import INCIDENT_TYPES, town_from_dict

    rng = np.random.default_rng(GRID_SEED)
    names = {(r, c): f"J{r}x{c}" for r in range(rows) for c in range(columns)}
    junctions = {name: [200.0 * c, 200.0 * r] for (r, c), name in names.items()}
    roads = [[names[r, c], names[r2, c2]] for (r, c) in names for r2, c2 in ((r + 1, c), (r, c + 1))
             if (r2, c2) in names]
    incidents = {f"{u}-{v}": str(rng.choice(INCIDENT_TYPES)) for a, b in roads for u, v in ((a, b), (b, a))}
    return town_from_dict({"junctions": junctions, "roads": roads, "incidents": incidents},
                          f"<grid {rows}x{columns}>")


def grid_spec_text(rows: int, columns: int) -> str:
    """φ1's shape on the grid: the waypoints are roads into the top-right and bottom-right corners,
    then into the bottom row four columns back (the corner on a 5 × 5 grid), the trust atom there:
    the trust-free route takes 14 (5 × 5) and 19 (5 × 10) junctions, within the horizon."""
    def into(r: int, c: int, r2: int, c2: int) -> str:
        return f"J{r}x{c}-J{r2}x{c2}"

    r9, c9 = rows - 1, columns - 1
    c3 = max(0, c9 - 4)
    return (f'name = "grid_phi1_trust"\nstart = "{into(0, 1, 0, 0)}"\n'
            'formula = "F (v1 & F (v2 & F (v3 & trusting)))"\n[states]\n'
            f'v1 = ["{into(0, c9 - 1, 0, c9)}", "{into(1, c9, 0, c9)}"]\n'
            f'v2 = ["{into(r9, c9 - 1, r9, c9)}", "{into(r9 - 1, c9, r9, c9)}"]\n'
            f'v3 = ["{into(r9, c3 + 1, r9, c3)}", "{into(r9 - 1, c3, r9, c3)}"]\n'
            "[trust_states]\ntrusting = { trust = [6, 7] }\n")


def _problem(town_kind: str):
    from trustroute.networks.town import load_town
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.policies.logic.spec import load_spec, spec_from_text
    from trustroute.policies.model.trust_pomdp import build_pomdp

    if town_kind == "paper":
        town = load_town()
        spec = load_spec("specs/phi1_trust.toml", town)
    else:
        rows, columns = GRIDS[town_kind]
        town = grid_town(rows, columns)
        spec = spec_from_text(grid_spec_text(rows, columns), f"<{town_kind} spec>", town)
    return build_pomdp(town, load_driver_model()), spec


GRIDS = {"grid25": (5, 5), "grid50": (5, 10)}


def _storm(queue, town_kind: str) -> None:
    from trustroute.policies.peer.product_pomdp import explicit_product
    from trustroute.policies.peer.storm import run_storm

    pomdp, spec = _problem(town_kind)
    started = time.perf_counter()
    product = explicit_product(pomdp, spec, HORIZON)
    export_seconds = time.perf_counter() - started
    result = run_storm(product, time_limit=STORM_TIME_LIMIT, resolution=STORM_RESOLUTION)
    queue.put({"lower": result.lower, "upper": result.upper, "product_states": product.n_states,
               "seconds": export_seconds + result.build_seconds + result.lower_seconds
               + result.upper_seconds, "lower_seconds": result.lower_seconds,
               "upper_seconds": result.upper_seconds, "lower_beliefs": result.lower_beliefs,
               "lower_complete": result.lower_complete,
               "peak_rss_mb": peak_rss_mb()})


def _ours(queue, town_kind: str) -> None:
    from trustroute.policies.synthesize_spec import synthesize_spec

    pomdp, spec = _problem(town_kind)
    started = time.perf_counter()
    result = synthesize_spec(pomdp, spec,
                             SynthesisSettings(tau=OUR_TAU, time_limit=OUR_TIME_LIMIT, horizon=HORIZON))
    last = result.stats.runs[-1]
    queue.put({"lower": result.lower, "upper": result.upper,
               "lower_is": "the returned policy's exact value (trustroute synth)",
               "search_lower": result.stats.search_lower, "policy_rows": result.stats.policy_rows,
               "max_nodes_per_level": last.max_nodes, "nodes": last.bounds.nodes,
               "cut_nodes": last.bounds.cut_nodes, "seconds": time.perf_counter() - started,
               "peak_rss_mb": peak_rss_mb()})


def run(town_kinds: tuple[str, ...] = ("paper", "grid25", "grid50")) -> list[dict]:
    from trustroute.policies.peer.storm import storm_available

    if not storm_available():
        return [{"name": "storm_vs_ours", "skipped": "stormpy absent: pip install -e '.[peer]'"}]
    results = []
    for kind in town_kinds:
        storm = in_spawned_process(_storm, kind)
        ours = in_spawned_process(_ours, kind)
        results.append({
            "name": f"storm_vs_ours_{kind}_phi1_trust_h{HORIZON}", "horizon": HORIZON, "storm": storm,
            "ours": ours, "storm_gap": storm["upper"] - storm["lower"],
            "ours_gap": ours["upper"] - ours["lower"],
            "time_ratio_ours_over_storm": ours["seconds"] / storm["seconds"],
            "memory_ratio_ours_over_storm": ours["peak_rss_mb"] / storm["peak_rss_mb"],
            "overlap": max(storm["lower"], ours["lower"]) <= min(storm["upper"], ours["upper"]) + 1e-6,
        })
    return results
